"""Label helpers shared by the paper and compact encodings (spec 3 vocabularies and aliases)."""

from __future__ import annotations

from collections.abc import Sequence

from rcbht_introspection.grammar.split import SubtaskSample
from rcbht_introspection.taxonomy.words import Level

LABEL_ALIASES: dict[str, str] = {"const": "cons"}
"""Spellings of the same label in the original files ('const' = 'cons', spec 3)."""


def label_index(level: Level, label: str) -> int:
    """0-based index of `label` in its level's vocabulary (spec 3); -1 if unknown."""
    label = LABEL_ALIASES.get(label.strip(), label.strip())
    try:
        return level.labels.index(label)
    except ValueError:
        return -1


def sample_arms(samples: Sequence[SubtaskSample]) -> tuple[str, ...]:
    """Arms present in the samples (sorted), e.g. ('R',) or ('L', 'R')."""
    arms: set[str] = set()
    for sample in samples:
        arms.update(sample.words.arms)
    return tuple(sorted(arms)) or ("R",)

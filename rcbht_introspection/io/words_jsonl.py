"""Words as JSON lines: one object per word, for tools outside the RCBHT file format."""

from __future__ import annotations

import json
from pathlib import Path

from rcbht_introspection.taxonomy.words import AXES, Level, TrialWords, Word


def word_record(trial: str, word: Word) -> dict[str, object]:
    """One JSON-lines record: the word's trial, place, label, span, sub-labels and features."""
    return {
        "trial": trial,
        "arm": word.arm,
        "axis": word.axis,
        "level": word.level.value,
        "label": word.label,
        "start": word.start,
        "end": word.end,
        "sublabels": list(word.sublabels),
        "features": word.features,
        "seq": word.seq,
    }


def write_jsonl(words: TrialWords, path: Path) -> None:
    """All words, level by level and axis by axis, one JSON object per line."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w") as fh:
        for arm in words.arms:
            for level in (Level.PRIMITIVE, Level.COMPOSITION, Level.BEHAVIOR):
                for axis in AXES:
                    for word in words.axis_words(arm, level, axis):
                        fh.write(json.dumps(word_record(words.name, word)) + "\n")

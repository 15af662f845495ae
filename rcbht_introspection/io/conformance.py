"""Conformance with the original RCBHT: our words against a trial's golden/ output files.

The composition and behaviour levels are compared record by record (label and the four span
times within TOLERANCE); the first difference is reported so a mismatch can be found by eye.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.rcbht_format import level_path, read_words
from rcbht_introspection.taxonomy.words import AXES, Level, TrialWords, Word

TIME_KEYS = ("t1Start", "t1End", "t2Start", "t2End")
CONFORMANCE_LEVELS = (Level.COMPOSITION, Level.BEHAVIOR)
TOLERANCE = 1e-4
"""Largest difference of a span time (s): the golden files hold 5 decimals."""


def first_difference(ours: list[Word], golden: list[Word]) -> str | None:
    """Where two record lists first differ in label or any of the four MC/LLB times."""
    for i, (a, b) in enumerate(zip(ours, golden, strict=False)):
        if a.label != b.label:
            return f"record {i + 1}: label {a.label!r} != golden {b.label!r}"
        for key in TIME_KEYS:
            x, y = a.features.get(key, float("nan")), b.features.get(key, float("nan"))
            if not abs(x - y) <= TOLERANCE:
                return f"record {i + 1} ({a.label}): {key} {x:.5f} != golden {y:.5f}"
    if len(ours) != len(golden):
        return f"{len(ours)} records != golden {len(golden)}"
    return None


def compare_trial(folder: Path, words: TrialWords) -> Iterable[tuple[Level, str, str | None]]:
    """(level, axis, first difference or None) for each golden Composites/llBehaviors file."""
    arm = words.arms[0] if words.arms else "R"
    for level in CONFORMANCE_LEVELS:
        for axis in AXES:
            path = level_path(folder / "golden", level, axis)
            try:
                golden = read_words(path, level, axis, arm)
            except InputError as exc:
                yield level, axis, f"golden file unreadable: {exc}"
                continue
            yield level, axis, first_difference(words.axis_words(arm, level, axis), golden)

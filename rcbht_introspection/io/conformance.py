"""Conformance with the original RCBHT: our words against a trial's golden/ output files.

The composition and behaviour levels are compared record by record (label and the four span
times within TOLERANCE); the first difference is reported so a mismatch can be found by eye.
A two-arm trial's golden files are per arm (golden/L/..., golden/R/..., as `rcbht label` writes
them); every arm is compared.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.hiro import ARMS
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


def golden_roots(folder: Path, arms: Sequence[str] = ARMS) -> dict[str, Path]:
    """Arm -> its golden root in a trial folder: golden/<arm>/ (or golden/<arm>_golden/), as
    write_trial_words lays out two arms; else golden/ itself for the one arm (or R of two)."""
    root = Path(folder) / "golden"
    found = {}
    for arm in arms:
        for candidate in (root / arm, root / f"{arm}_golden"):
            if level_path(candidate, Level.PRIMITIVE, AXES[0]).is_file():
                found[arm] = candidate
                break
    if not found and level_path(root, Level.PRIMITIVE, AXES[0]).is_file():
        found[arms[0] if len(arms) == 1 else "R"] = root
    return found


def compare_arms(folder: Path, words: TrialWords) -> Iterable[tuple[str, Level, str, str | None]]:
    """(arm, level, axis, first difference or None) for every arm of `words` and each of its
    golden Composites/llBehaviors files; an arm without golden files differs in every file."""
    arms = words.arms or ("R",)
    roots = golden_roots(folder, arms)
    for arm in arms:
        root = roots.get(arm)
        for level in CONFORMANCE_LEVELS:
            for axis in AXES:
                if root is None:
                    yield arm, level, axis, f"no golden files of arm {arm} (golden/{arm}/)"
                    continue
                yield arm, level, axis, _compare_file(root, level, axis, words, arm)


def _compare_file(root: Path, level: Level, axis: str, words: TrialWords, arm: str) -> str | None:
    path = level_path(root, level, axis)
    try:
        golden = read_words(path, level, axis, arm)
    except InputError as exc:
        return f"golden file unreadable: {exc}"
    return first_difference(words.axis_words(arm, level, axis), golden)

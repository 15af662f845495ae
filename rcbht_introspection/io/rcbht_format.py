"""The original RCBHT text format: Segments/Composites/llBehaviors files of "Key : value" records.

Records are separated by blank lines; numbers are written with 5 decimals, as v2.0.2 does, so
our output diffs against the golden files and feeds the original downstream tools.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rcbht_introspection.errors import InputError
from rcbht_introspection.taxonomy.words import AXES, Level, TrialWords, Word


@dataclass(frozen=True)
class LevelFormat:
    """File layout of one level: folder, file stem, record keys, label key, span keys, key width."""

    folder: str
    stem: str
    keys: tuple[str, ...]
    label_key: str
    start_key: str
    end_key: str
    key_width: int


FORMATS: dict[Level, LevelFormat] = {
    Level.PRIMITIVE: LevelFormat(
        "Segments", "Segement",
        ("Iteration", "Average", "Max Val", "Min Val", "Start", "Finish", "Gradient", "Grad Label"),
        "Grad Label", "Start", "Finish", 10,
    ),
    Level.COMPOSITION: LevelFormat(
        "Composites", "Composites",
        ("Iteration", "Label", "Average Val", "RMS Val", "Amplitude Val", "Label 1", "Label 2",
         "t1Start", "t1End", "t2Start", "t2End", "tAvgIndex"),
        "Label", "t1Start", "t2End", 14,
    ),
    Level.BEHAVIOR: LevelFormat(
        "llBehaviors", "llBehaviors",
        ("Iteration", "CompLabel", "averageVal1", "averageVal2", "AVG_MAG_VAL", "rmsVal1",
         "rmsVal2", "AVG_RMS_Val", "amplitudeVal1", "amplitudeVal2", "AVG_AMP_VAL", "Label 1",
         "Label 2", "t1Start", "t1End", "t2Start", "t2End", "tAvgIndex"),
        "CompLabel", "t1Start", "t2End", 14,
    ),
}  # fmt: skip
TEXT_KEYS = frozenset({"Grad Label", "Label", "CompLabel", "Label 1", "Label 2"})


def level_path(root: Path, level: Level, axis: str) -> Path:
    """Path of one level/axis file under a trial's output (or golden/) folder."""
    fmt = FORMATS[level]
    return Path(root) / fmt.folder / f"{fmt.stem}_{axis}.txt"


def read_records(path: Path) -> list[dict[str, str]]:
    """Parse a file into records of raw string values; malformed lines give a one-line error."""
    records: list[dict[str, str]] = []
    current: dict[str, str] = {}
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=path) from exc
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        key, sep, value = line.partition(":")
        if not sep:
            raise InputError("expected 'Key : value'", path=path, line=number)
        key = key.strip()
        # A record starts at 'Iteration' or at a repeated key; blank lines are not trusted as
        # separators (later code states write an empty 'Label 2' followed by a blank line).
        if current and (key == "Iteration" or key in current):
            records.append(current)
            current = {}
        current[key] = value.strip()
    if current:
        records.append(current)
    return records


def read_words(path: Path, level: Level, axis: str, arm: str = "R") -> list[Word]:
    """Read one level/axis file as words (numeric fields in `features`, labels as text)."""
    fmt = FORMATS[level]
    words = []
    for index, record in enumerate(read_records(path)):
        features: dict[str, float] = {}
        for key, value in record.items():
            if key in TEXT_KEYS or key == "Iteration":
                continue
            try:
                features[key] = float(value)
            except ValueError:
                raise InputError(
                    f"record {index + 1}: not a number: {value!r}", path=path, field=key
                ) from None
        for key in (fmt.label_key, fmt.start_key, fmt.end_key):
            if key not in record:
                raise InputError(f"record {index + 1}: missing key", path=path, field=key)
        extra = {k: record[k] for k in ("Label 1", "Label 2") if k in record}
        words.append(
            Word(
                axis=axis,
                level=level,
                label=record[fmt.label_key],
                start=features[fmt.start_key],
                end=features[fmt.end_key],
                features=features,
                arm=arm,
                seq=index,
                sublabels=tuple(extra.values()),
            )
        )
    return words


def read_trial_words(
    root: Path,
    name: str = "",
    arm: str = "R",
    levels: Iterable[Level] = (Level.COMPOSITION, Level.BEHAVIOR),
) -> TrialWords:
    """Read the words of all axes for the given levels from an output or golden/ folder."""
    result = TrialWords(name=name or Path(root).parent.name)
    for level in levels:
        for axis in AXES:
            for word in read_words(level_path(root, level, axis), level, axis, arm):
                result.add(word)
    return result


_TEMPLATES: dict[Level, tuple[str, tuple[tuple[str, Any], ...]]] = {}
_NAN = float("nan")


def _template(level: Level) -> tuple[str, tuple[tuple[str, Any], ...]]:
    """The record layout of a level as one str.format template and what fills each field."""
    cached = _TEMPLATES.get(level)
    if cached is not None:
        return cached
    fmt = FORMATS[level]
    parts: list[str] = []
    fills: list[tuple[str, Any]] = []  # (kind, argument): a feature key or sub-label index
    for key in fmt.keys:
        pad = key if level is Level.PRIMITIVE and key == "Grad Label" else f"{key:<{fmt.key_width}}"
        fill: tuple[str, Any]
        if key == "Iteration":
            spec, fill = "{}", ("iteration", None)
        elif key == fmt.label_key:
            spec, fill = ("{:<6}" if level is Level.PRIMITIVE else "{}"), ("label", None)
        elif key in ("Label 1", "Label 2"):
            spec, fill = "{}", ("sub", int(key[-1]) - 1)
        else:
            spec, fill = "{:.5f}", ("feature", key)
        parts.append(f"{pad}: {spec}")
        fills.append(fill)
    _TEMPLATES[level] = ("\n".join(parts) + "\n", tuple(fills))
    return _TEMPLATES[level]


def format_record(level: Level, iteration: int, word: Word) -> str:
    """One record in the original layout ('Key : value', values with 5 decimals)."""
    template, fills = _template(level)
    features, sub = word.features, word.sublabels
    values: list[object] = []
    for kind, arg in fills:
        if kind == "feature":
            values.append(features.get(arg, _NAN))
        elif kind == "sub":
            values.append(sub[arg] if arg < len(sub) else _NAN)
        elif kind == "label":
            values.append(word.label)
        else:
            values.append(iteration)
    return template.format(*values)


def write_words(path: Path, level: Level, words: Iterable[Word]) -> None:
    """Write one level/axis file; iterations are numbered from 1 in list order."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = "\n".join(format_record(level, i, w) for i, w in enumerate(words, start=1))
    path.write_text(text + ("\n" if text else ""))


def write_trial_words(words: TrialWords, folder: Path) -> None:
    """A trial in the original layout: Segments/Composites/llBehaviors per axis (one sub-folder
    per arm when there are two), diffable against golden/ files."""
    arms = words.arms
    for arm in arms:
        root = folder if len(arms) == 1 else folder / arm
        for level in (Level.PRIMITIVE, Level.COMPOSITION, Level.BEHAVIOR):
            for axis in AXES:
                write_words(
                    level_path(root, level, axis), level, words.axis_words(arm, level, axis)
                )

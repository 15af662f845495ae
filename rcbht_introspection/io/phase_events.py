"""Sub-task phases of an imported bag: integer phase maps, phase CSV files, and the rule that
turns timed phase events into a trial's phases.

Rule (docs/bags.md, "Importing bags from another robot"): events are taken in order; events
outside the task (OUT) before the first task phase are skipped and counted; the trial then runs
until an end phase or the next event outside the task, and later events are counted, not used; an
event naming the phase that is running continues it (counted as repeated); a phase with no sample
(the next one starts at the same time, or it starts at or after the last sample) is dropped and
counted.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from rcbht_introspection.errors import InputError

END = ""
"""Name of a phase-map value that means 'the end phase' (written `3=`)."""
OUT = "-"
"""Name of a phase outside the task (written `0=-`; a string phase or CSV row `-`): the robot idle
before or after the task. It is neither a sub-task nor the end phase."""
CSV_COLUMNS = {"time": False, "stamp": True}
"""First column of a phase CSV -> its times are absolute stamps (else seconds from the bag's
first wrench sample)."""


def parse_phase_map(text: str) -> dict[int, str]:
    """`0=reach,1=grasp,3=` -> {0: 'reach', 1: 'grasp', 3: END}."""
    mapping: dict[int, str] = {}
    for item in (p.strip() for p in text.split(",")):
        value, sep, name = item.partition("=")
        try:
            key = int(value)
        except ValueError:
            key = None
        if not sep or key is None:
            raise InputError(
                f"{item!r} is not VALUE=NAME (an integer, '=', a name)", field="--phase-map"
            )
        if key in mapping:
            raise InputError(f"value {key} is named twice", field="--phase-map")
        mapping[key] = name.strip()
    return mapping


@dataclass(frozen=True)
class PhaseCsv:
    """Rows (seconds, phase name) of a phase CSV file; `absolute`: the times are stamps."""

    path: Path
    absolute: bool
    rows: tuple[tuple[float, str], ...]


def _phase_row(cells: list[str], time_column: str, path: Path, number: int) -> tuple[float, str]:
    """(seconds, phase name) of one CSV line: a finite number and a name that is not empty."""
    if len(cells) != 2:
        raise InputError(f"expected 2 columns, got {len(cells)}", path, line=number)
    try:
        seconds = float(cells[0])
        if not math.isfinite(seconds):
            raise ValueError
    except ValueError:
        raise InputError(
            f"not a number: {cells[0]!r}", path, line=number, field=time_column
        ) from None
    name = cells[1].strip()
    if not name:
        raise InputError("empty phase name", path, line=number, field="phase")
    return seconds, name


def read_phase_csv(path: Path | str) -> PhaseCsv:
    """A CSV file `time,phase` (seconds from the first wrench sample) or `stamp,phase` (absolute
    seconds, the clock of the wrench stamps), one event per line, times not decreasing."""
    path = Path(path)
    try:
        with path.open(newline="") as handle:
            lines = list(csv.reader(handle))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"cannot read phase CSV: {exc}", path) from None
    header = [c.strip() for c in lines[0]] if lines else []
    if len(header) != 2 or header[0] not in CSV_COLUMNS or header[1] != "phase":
        raise InputError(
            f"header must be 'time,phase' or 'stamp,phase', not {','.join(header)!r}", path, line=1
        )
    rows: list[tuple[float, str]] = []
    for number, cells in enumerate(lines[1:], start=2):
        if not any(c.strip() for c in cells):
            continue
        seconds, name = _phase_row(cells, header[0], path, number)
        if rows and seconds < rows[-1][0]:
            raise InputError(
                f"{seconds} comes before the previous time {rows[-1][0]}",
                path,
                line=number,
                field=header[0],
            )
        rows.append((seconds, name))
    if not rows:
        raise InputError("no phase events", path)
    return PhaseCsv(path, CSV_COLUMNS[header[0]], tuple(rows))


def phase_name(
    value: object,
    phase_map: Mapping[int, str] | None,
    end_phases: Collection[str],
    bag: Path | str,
    source: str,
    out_of_task: Collection[str] = (),
) -> str | None:
    """The phase a source value names: None for an end phase, OUT for a phase outside the task
    (`-`, or a name in `out_of_task`); an integer goes through the map."""
    if phase_map is not None:
        assert isinstance(value, int)
        if value not in phase_map:
            named = ", ".join(map(str, sorted(phase_map)))
            raise InputError(
                f"value {value} has no name in --phase-map (named: {named}); a value outside "
                "the task is named '-'",
                bag,
                field=source,
            )
        name = phase_map[value]
    else:
        name = str(value).strip()
        if not name:
            raise InputError("an empty phase name", bag, field=source)
    if name == OUT or name in out_of_task:
        return OUT
    return None if name == END or name in end_phases else name


@dataclass(frozen=True)
class PhaseCounts:
    """What happened to the phase events of one bag (stored in the output bag's trial info)."""

    events: int
    """Phase events read (messages of the phase topic or rows of the CSV)."""
    repeated: int
    """Events that named the phase already running: merged into it."""
    empty: int
    """Phases without a sample: dropped."""
    after_end: int
    """Events after the end (the end phase or the first event outside the task): not used."""
    end: str
    """'source': the source named the end phase; 'out_of_task': the first event outside the
    task after a task phase ended the trial; 'appended': it ends at the last sample."""
    before_first_phase: int = 0
    """Events outside the task before the first task phase: skipped."""
    resumed: int = 0
    """Task phase events among those after the end (the task went on after an end phase or an
    out-of-task stretch): not in the trial."""


@dataclass(frozen=True)
class TaskSpan:
    """The phase events of the trial: from the first task phase to the end."""

    phases: list[tuple[int, str]]
    """(stamp, name) of each task phase event before the end."""
    end_ns: int | None
    """Stamp of the event that ended the trial; None: no event did (it ends at the last sample)."""
    end: str
    """PhaseCounts.end: 'source', 'out_of_task' or 'appended'."""
    before_first_phase: int
    """Events outside the task before the first task phase."""
    after_end: int
    resumed: int


def task_span(events: Sequence[tuple[int, str | None]]) -> TaskSpan:
    """The span of (stamp, name) events whose name is a task phase, None (an end phase) or OUT:
    events outside the task are skipped until the first task phase, after which an end phase or
    an event outside the task ends the trial. An end phase before any task phase leaves no
    phases."""
    phases: list[tuple[int, str]] = []
    before = 0
    for i, (stamp, name) in enumerate(events):
        if name == OUT and not phases:
            before += 1
            continue
        if name is None or name == OUT:
            rest = events[i + 1 :]
            resumed = sum(n is not None and n != OUT for _, n in rest)
            end = "source" if name is None else "out_of_task"
            return TaskSpan(phases, stamp, end, before, len(rest), resumed)
        phases.append((stamp, name))
    return TaskSpan(phases, None, "appended", before, 0, 0)


def _merge_repeats(phases: list[tuple[float, str]]) -> tuple[list[tuple[float, str]], int]:
    merged: list[tuple[float, str]] = []
    for t, name in phases:
        if merged and merged[-1][1] == name:
            continue
        merged.append((t, name))
    return merged, len(phases) - len(merged)


def usable_phases(
    phases: Sequence[tuple[float, str]], end_time: float
) -> tuple[list[tuple[float, str]], int, int]:
    """(phases with samples, repeated events merged, empty phases dropped) of (start s, name)
    phases whose starts do not decrease, for a trial whose last sample is at `end_time`."""
    merged, repeated = _merge_repeats(list(phases))
    kept = [
        (t, name)
        for i, (t, name) in enumerate(merged)
        if t < (merged[i + 1][0] if i + 1 < len(merged) else end_time)
    ]
    empty = len(merged) - len(kept)
    kept, again = _merge_repeats(kept)
    return kept, repeated + again, empty

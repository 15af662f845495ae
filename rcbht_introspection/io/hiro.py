"""HIRO trial folders: `<arm>_Torques.dat` (t Fx Fy Fz Mx My Mz) and `<arm>_State.dat`.

Malformed input raises InputError naming file, line and field (the CLI prints it, exit code 2).
State times policy (docs/your-robot.md): a state time after the trial's last sample, or before
the previous kept one, is dropped and recorded in the trial's metadata (DROPPED_STATE_TIMES);
with `strict` each is an error, as is any other malformed line.
"""

from __future__ import annotations

import io
import json
import math
import os
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import yaml

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.sensor_checks import (
    REPEATED_METADATA,
    RepeatedPolicy,
    resolve_repeated_stamps,
)
from rcbht_introspection.io.trial import AXES, Trial, check_phases
from rcbht_introspection.task import HIRO_TASK, TASK_FILE, Task, task_of_folder

META_FILE = "meta.json"
"""A trial folder's metadata (the simulator's draw); read_trial takes its failure record."""
FAILURE_RECORD = "failure"
"""Metadata key of a failed trial's class, onset and deviation (verify/labels.py)."""
SESSION_RECORD = "session"
"""Metadata key of the recording session a trial belongs to (verify/labels.py)."""
DROPPED_STATE_TIMES = "dropped_state_times"
"""Metadata key of the state times read_trial dropped: a list of {line, time, reason}."""
DropReason = Literal["after the data", "out of order"]

COLUMNS: tuple[str, ...] = ("t", *AXES)
ARMS: tuple[str, ...] = ("L", "R")


def _ordered(steps: np.ndarray, allow_repeated: bool) -> bool:
    """Every time step positive (or, allowing repeated times, none negative)."""
    return bool((steps >= 0).all() if allow_repeated else (steps > 0).all())


def _fast_table(text: str, columns: tuple[str, ...], allow_repeated: bool) -> np.ndarray | None:
    """The table by NumPy's C parser when it is well formed (every value finite, time in
    order); None sends it to the line-by-line parser, which names the problem."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fast = np.loadtxt(io.StringIO(text), dtype=np.float64, comments=None, ndmin=2)
        if (
            fast.shape[0] > 0
            and fast.shape[1] == len(columns)
            and np.isfinite(fast).all()
            and (fast.shape[0] == 1 or _ordered(np.diff(fast[:, 0]), allow_repeated))
        ):
            return np.ascontiguousarray(fast)
    except ValueError:
        pass
    return None


def _table_row(parts: list[str], columns: tuple[str, ...], path: Path, lineno: int) -> list[float]:
    """The finite numbers of one table line, one per column (else an InputError naming it)."""
    if len(parts) != len(columns):
        raise InputError(f"expected {len(columns)} columns, found {len(parts)}", path, lineno)
    row = []
    for name, part in zip(columns, parts, strict=True):
        try:
            value = float(part)
        except ValueError:
            raise InputError(f"not a number: {part!r}", path, lineno, name) from None
        if not math.isfinite(value):
            raise InputError(f"not a finite number: {part!r}", path, lineno, name)
        row.append(value)
    return row


def read_table(
    path: Path, columns: tuple[str, ...] = COLUMNS, allow_repeated: bool = False
) -> np.ndarray:
    """Parse a whitespace table of len(columns) numeric columns; time (column 0) strictly increasing
    (with `allow_repeated`, a time may equal the one before it: io/sensor_checks resolves those).

    Fast path: NumPy's C parser, accepted only if every value is finite and time increases;
    anything else is re-parsed line by line to name the file, line and field of the problem.
    """
    try:
        text = path.read_text()
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=path) from None
    fast = _fast_table(text, columns, allow_repeated)
    if fast is not None:
        return fast
    rows: list[list[float]] = []
    last_t = -math.inf
    for lineno, line in enumerate(text.splitlines(), start=1):
        parts = line.split()
        if not parts:
            continue
        row = _table_row(parts, columns, path, lineno)
        if row[0] < last_t or (row[0] == last_t and not allow_repeated):
            hint = "" if allow_repeated or row[0] < last_t else "; see --repeated-stamps"
            raise InputError(
                f"time does not increase ({row[0]} after {last_t}){hint}",
                path,
                lineno,
                columns[0],
            )
        last_t = row[0]
        rows.append(row)
    if not rows:
        raise InputError("no samples", path)
    return np.asarray(rows, dtype=np.float64)


@dataclass(frozen=True)
class DroppedStateTime:
    """A state time the policy dropped: its line in the state file, value and why."""

    line: int
    time: float
    reason: DropReason

    def to_dict(self) -> dict[str, object]:
        return {"line": self.line, "time": self.time, "reason": self.reason}


@dataclass(frozen=True)
class StateTimes:
    """The state times of a state file that the policy kept, and the ones it dropped."""

    times: tuple[float, ...] = ()
    positions: tuple[int, ...] = ()
    """Position of each kept time among the file's times (0: its first): the sub-task it starts."""
    dropped: tuple[DroppedStateTime, ...] = ()
    path: Path | None = None

    def named(self, task: Task) -> tuple[tuple[float, ...], tuple[str, ...]]:
        """(times, phase names) of the kept times for `task`; names () mean HIRO's in order. A
        time keeps the sub-task of its position, so a time dropped in the middle leaves that
        sub-task out instead of shifting the names after it; times beyond the task's sub-tasks
        are left out, except HIRO's own extra lines when nothing is missing."""
        if self.positions == tuple(range(len(self.times))):
            if task == HIRO_TASK:
                return self.times, ()
            times = self.times[: len(task.subtasks)]
            return times, task.subtasks[: len(times)]
        named = [
            (t, task.subtasks[p])
            for t, p in zip(self.times, self.positions, strict=True)
            if p < len(task.subtasks)
        ]
        return tuple(t for t, _ in named), tuple(n for _, n in named)


def _state_lines(path: Path) -> list[tuple[int, float]]:
    """(line number, value) of every non-empty line; a line that is not a finite number is an
    error."""
    values: list[tuple[int, float]] = []
    for lineno, line in enumerate(path.read_text().splitlines(), start=1):
        if not line.strip():
            continue
        try:
            value = float(line.split()[0])
        except ValueError:
            raise InputError(
                f"not a number: {line.strip()!r}", path, lineno, "state time"
            ) from None
        if not math.isfinite(value):
            raise InputError(f"not a finite number: {value}", path, lineno, "state time")
        values.append((lineno, value))
    return values


def read_state_times(path: Path, end_time: float | None = None, strict: bool = False) -> StateTimes:
    """Sub-task start times of a state file, one per line (none: an empty StateTimes; failed
    trials may have none). A time after `end_time` (the last sample) or before the previous kept
    time is dropped and recorded; with `strict` a time out of order is an error, and one after
    the data is kept (read_trial's check_phases names it)."""
    if not path.is_file():
        return StateTimes(path=path)
    times: list[float] = []
    positions: list[int] = []
    dropped: list[DroppedStateTime] = []
    for position, (lineno, value) in enumerate(_state_lines(path)):
        reason: DropReason | None = None
        if times and value < times[-1]:
            if strict:
                raise InputError(f"state time out of order: {value}", path, lineno, "state time")
            reason = "out of order"
        if not strict and end_time is not None and value > end_time:
            reason = "after the data"
        if reason is not None:
            dropped.append(DroppedStateTime(lineno, value, reason))
            continue
        times.append(value)
        positions.append(position)
    return StateTimes(tuple(times), tuple(positions), tuple(dropped), path)


def trial_state_times(folder: Path, end_time: float | None, strict: bool = False) -> StateTimes:
    """The state times of a trial folder: R_State.dat's, else L_State.dat's (read_state_times)."""
    state = read_state_times(folder / "R_State.dat", end_time, strict)
    if state.times or state.dropped:
        return state
    return read_state_times(folder / "L_State.dat", end_time, strict)


def dropped_state_times(trial: Trial) -> int:
    """How many state times read_trial dropped from the trial (0 for a bag or a clean folder)."""
    dropped = trial.metadata.get(DROPPED_STATE_TIMES)
    return len(dropped) if isinstance(dropped, list) else 0


def dropped_per_trial(counts: Mapping[str, int]) -> dict[str, object]:
    """The JSON record of dropped state times: {"total": n, "per_trial": {trial: n}} (trials
    that dropped none left out)."""
    per_trial = {name: n for name, n in counts.items() if n}
    return {"total": sum(per_trial.values()), "per_trial": per_trial}


def read_trial(
    folder: Path | str, repeated: RepeatedPolicy | None = None, strict: bool = False
) -> Trial:
    """Load a HIRO trial folder (one arm R_*, or two arms L_* and R_*).

    A time equal to the previous row's is an error, or with a `repeated` policy resolved by
    io/sensor_checks (counts per arm in metadata['repeated_stamps']). A state time after the
    last sample or out of order is dropped (metadata[DROPPED_STATE_TIMES]; StateTimes.named
    keeps the others' sub-tasks), or with `strict` an error."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError("not a trial folder", folder)
    wrench: dict[str, np.ndarray] = {}
    time: np.ndarray | None = None
    repeats: dict[str, dict[str, int]] = {}
    for arm in ARMS:
        path = folder / f"{arm}_Torques.dat"
        if not path.is_file():
            continue
        table = read_table(path, allow_repeated=repeated is not None)
        arm_time, values = table[:, 0], table[:, 1:]
        if repeated is not None:
            arm_time, values, repeats[arm] = resolve_repeated_stamps(arm_time, values, repeated)
        if time is not None and (len(arm_time) != len(time) or not np.allclose(arm_time, time)):
            raise InputError("time column differs from the other arm's", path, field="t")
        time = arm_time
        wrench[arm] = np.ascontiguousarray(values)
    if time is None:
        raise InputError("no R_Torques.dat or L_Torques.dat", folder)
    states = trial_state_times(folder, float(time[-1]), strict)
    outcome_file = folder / "outcome.txt"
    outcome = outcome_file.read_text().strip() if outcome_file.is_file() else "success"
    task = task_of_folder(folder)
    state, phases = states.named(task)  # HIRO's own trials keep their extra lines
    metadata: dict[str, object] = {REPEATED_METADATA: repeats} if repeats else {}
    if states.dropped:
        metadata[DROPPED_STATE_TIMES] = [d.to_dict() for d in states.dropped]
    if task != HIRO_TASK:
        metadata["task"] = task.to_dict()  # a bag written from the trial keeps its task
    metadata.update(_meta_records(folder / META_FILE))
    trial = Trial(folder.name, time, wrench, state, outcome, metadata, phases)
    check_phases(trial, folder / ("R_State.dat" if "R" in wrench else "L_State.dat"))
    return trial


def _meta_records(path: Path) -> dict[str, object]:
    """What the verifier reads of a trial's meta.json: the failure record (class, onset,
    deviation: verify/labels.py) and the recording session's name."""
    if not path.is_file():
        return {}
    try:
        meta = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"not readable JSON ({type(exc).__name__})", path) from None
    meta = meta if isinstance(meta, dict) else {}
    out: dict[str, object] = {}
    record = meta.get(FAILURE_RECORD)
    if record is not None and not isinstance(record, dict):
        raise InputError("must be a mapping", path, field=FAILURE_RECORD)
    if record is not None:
        out[FAILURE_RECORD] = record
    session = meta.get(SESSION_RECORD)
    if session is not None and not isinstance(session, str):
        raise InputError("must be a string", path, field=SESSION_RECORD)
    if session:
        out[SESSION_RECORD] = session
    return out


def write_trial(trial: Trial, folder: Path | str, task: Task | None = None) -> Path:
    """Write `trial` in the HIRO layout (<arm>_Torques.dat, <arm>_State.dat, outcome.txt), and
    task.yaml when its sub-tasks are not HIRO's (`task`, else the trial's phase names)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for arm, wrench in trial.wrench.items():
        table = np.column_stack([trial.time, wrench])
        np.savetxt(folder / f"{arm}_Torques.dat", table, fmt="%.9g", delimiter="\t")
        (folder / f"{arm}_State.dat").write_text("".join(f"{t:.6g}\n" for t in trial.state_times))
    (folder / "outcome.txt").write_text(trial.outcome + "\n")
    if isinstance(trial.metadata.get(FAILURE_RECORD), dict):
        record = {FAILURE_RECORD: trial.metadata[FAILURE_RECORD]}
        (folder / META_FILE).write_text(json.dumps(record, indent=1) + "\n")
    names = trial.phase_names
    stored = trial.metadata.get("task")
    if task is None and isinstance(stored, dict):
        task = Task.from_dict(stored)  # the task the trial was read or simulated with
    if task is None and trial.phases and names != HIRO_TASK.subtasks[: len(names)]:
        task = Task(names)
        if len(set(names)) != len(names):
            raise InputError(
                f"a trial folder cannot repeat a sub-task ({list(names)}); write a bag"
            )
    if task is not None and task != HIRO_TASK:
        if tuple(names) != task.subtasks[: len(names)]:
            raise InputError(
                f"phases {list(names)} are not a start of the task's sub-tasks "
                f"{list(task.subtasks)} (a trial folder holds times only); write a bag",
                folder,
            )
        (folder / TASK_FILE).write_text(yaml.safe_dump(task.to_dict(), sort_keys=False))
    return folder


def find_trials(paths: list[Path] | list[str]) -> list[Path]:
    """Trial folders among `paths`: each is a trial folder or a dataset folder of trials (sorted)."""
    found: list[Path] = []
    for p in map(Path, paths):
        if (p / "R_Torques.dat").is_file() or (p / "L_Torques.dat").is_file():
            found.append(p)
        elif p.is_dir():
            found.extend(
                sorted(
                    c
                    for c in p.iterdir()
                    if (c / "R_Torques.dat").is_file() or (c / "L_Torques.dat").is_file()
                )
            )
        else:
            raise InputError("no such trial or dataset folder", p)
    return found


def hiro_root() -> Path:
    """The shared HIRO data: $RCBHT_HIRO_DATA, else ../shared/data/hiro beside the repository."""
    env = os.environ.get("RCBHT_HIRO_DATA")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[3] / "shared" / "data" / "hiro"


def shared_hiro() -> Path | None:
    """REAL_HIRO_ONE_SA_SUCCESS under `hiro_root()`, if present: the REAL HIRO trials that
    `rcbht demo --data hiro` and the ROS benchmarks use."""
    real = hiro_root() / "REAL_HIRO_ONE_SA_SUCCESS"
    return real if real.is_dir() else None

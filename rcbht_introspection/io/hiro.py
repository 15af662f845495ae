"""HIRO trial folders: `<arm>_Torques.dat` (t Fx Fy Fz Mx My Mz) and `<arm>_State.dat`.

Malformed input raises InputError naming file, line and field (the CLI prints it, exit code 2).
"""

from __future__ import annotations

import io
import json
import math
import os
import warnings
from pathlib import Path

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

COLUMNS: tuple[str, ...] = ("t", *AXES)
ARMS: tuple[str, ...] = ("L", "R")


def _ordered(steps: np.ndarray, allow_repeated: bool) -> bool:
    """Every time step positive (or, allowing repeated times, none negative)."""
    return bool((steps >= 0).all() if allow_repeated else (steps > 0).all())


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
    rows: list[list[float]] = []
    last_t = -math.inf
    for lineno, line in enumerate(text.splitlines(), start=1):
        parts = line.split()
        if not parts:
            continue
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


def read_state(path: Path) -> tuple[float, ...]:
    """Sub-task start times, one per line (may be empty for failed trials)."""
    if not path.is_file():
        return ()
    times: list[float] = []
    for lineno, line in enumerate(path.read_text().splitlines(), start=1):
        if not line.strip():
            continue
        try:
            value = float(line.split()[0])
        except ValueError:
            raise InputError(
                f"not a number: {line.strip()!r}", path, lineno, "state time"
            ) from None
        if not math.isfinite(value) or (times and value < times[-1]):
            raise InputError(f"state time out of order: {value}", path, lineno, "state time")
        times.append(value)
    return tuple(times)


def read_trial(folder: Path | str, repeated: RepeatedPolicy | None = None) -> Trial:
    """Load a HIRO trial folder (one arm R_*, or two arms L_* and R_*).

    A time equal to the previous row's is an error, or with a `repeated` policy resolved by
    io/sensor_checks (counts per arm in metadata['repeated_stamps'])."""
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
    state = read_state(folder / "R_State.dat")
    if not state:
        state = read_state(folder / "L_State.dat")
    outcome_file = folder / "outcome.txt"
    outcome = outcome_file.read_text().strip() if outcome_file.is_file() else "success"
    task = task_of_folder(folder)
    phases: tuple[str, ...] = ()
    metadata: dict[str, object] = {REPEATED_METADATA: repeats} if repeats else {}
    if task != HIRO_TASK:  # HIRO's own trials keep the default names (and their extra lines)
        state = state[: len(task.subtasks)]
        phases = task.subtasks[: len(state)]
        metadata["task"] = task.to_dict()  # a bag written from the trial keeps its task
    failure = _failure_record(folder / META_FILE)
    if failure is not None:
        metadata[FAILURE_RECORD] = failure
    trial = Trial(folder.name, time, wrench, state, outcome, metadata, phases)
    check_phases(trial, folder / ("R_State.dat" if "R" in wrench else "L_State.dat"))
    return trial


def _failure_record(path: Path) -> dict[str, object] | None:
    """The failure record (class, onset, deviation: verify/labels.py) of a trial's meta.json."""
    if not path.is_file():
        return None
    try:
        meta = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"not readable JSON ({type(exc).__name__})", path) from None
    record = meta.get(FAILURE_RECORD) if isinstance(meta, dict) else None
    if record is not None and not isinstance(record, dict):
        raise InputError("must be a mapping", path, field=FAILURE_RECORD)
    return record


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

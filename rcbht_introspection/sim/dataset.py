"""Write a simulated data set: one folder per trial in the HIRO layout, or one rosbag2 per trial.

Trial i of a set uses seed `seed * 1000 + i`; with failures on, every second trial is a failure,
cycling through the configured failure classes (each deviation class is one). A dataset-level sim_meta.json lists every trial's
outcome and variation; each HIRO trial folder also gets outcome.txt and meta.json, and task.yaml
when its task is not the snap assembly (bags carry the task in their trial info).
"""

from __future__ import annotations

import functools
import json
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, get_args

from rcbht_introspection.errors import InputError
from rcbht_introspection.fleet import parallel_map
from rcbht_introspection.io.bags import write_trial_bag
from rcbht_introspection.io.hiro import write_trial
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.sim.config import FailureType
from rcbht_introspection.sim.scenario import ScenarioName, get_scenario
from rcbht_introspection.sim.sessions import SessionSensor, draw_sessions, in_session, session_of
from rcbht_introspection.sim.tasks import (
    SimTask,
    SimTaskName,
    TaskConfig,
    TrialSimulator,
    check_request,
    get_sim_task,
    task_failure_classes,
    trial_simulator,
)

DatasetFormat = Literal["hiro", "bag"]
"""A data set is HIRO trial folders or one rosbag2 per trial."""
FORMATS: tuple[str, ...] = get_args(DatasetFormat)


def trial_plan(
    n_trials: int, seed: int, failures: bool, types: tuple[FailureType, ...]
) -> list[tuple[int, FailureType | None]]:
    """(trial seed, failure type or None) for each trial of a set."""
    plan: list[tuple[int, FailureType | None]] = []
    for i in range(n_trials):
        failure = types[(i // 2) % len(types)] if failures and i % 2 == 1 else None
        plan.append((seed * 1000 + i, failure))
    return plan


def trial_name(
    scenario: ScenarioName, index: int, failure: FailureType | None, label: str | None = None
) -> str:
    """Folder name in the HIRO style: SIM-<label>-S-<nn> or SIM-<label>-F-<nn>-<type>; the label
    is the task's (PEG), else the scenario's (ONE or TWO)."""
    arms = label or ("ONE" if scenario == "one-arm" else "TWO")
    if failure is None:
        return f"SIM-{arms}-S-{index + 1:02d}"
    return f"SIM-{arms}-F-{index + 1:02d}-{failure}"


def _clear_previous_set(out: Path) -> None:
    """Re-running into a folder replaces the previous simulated set; foreign trials are an error.

    A folder holding a sim_meta.json is our own earlier output: its listed trials are removed so no
    stale trial of a larger earlier set survives. A folder with other trial data is refused.
    """
    if not out.is_dir():
        return
    meta = out / "sim_meta.json"
    if meta.is_file():
        try:
            names = [t["name"] for t in json.loads(meta.read_text())["trials"]]
        except (ValueError, KeyError, TypeError):
            raise InputError(
                "unreadable sim_meta.json; remove the folder first", path=meta
            ) from None
        for name in names:
            shutil.rmtree(out / name, ignore_errors=True)
            for suffix in (".mcap", ".db3"):
                (out / f"{name}{suffix}").unlink(missing_ok=True)
        meta.unlink()
    if find_trials_in(out):
        raise InputError(
            "folder already holds trial data that this simulator did not write", path=out
        )


def find_trials_in(out: Path) -> list[Path]:
    """Trial folders or bag files directly inside `out`."""
    return sorted(
        p
        for p in out.iterdir()
        if p.suffix in (".mcap", ".db3")
        or (p / "R_Torques.dat").is_file()
        or (p / "L_Torques.dat").is_file()
    )


def _check_set(fmt: str, n_trials: int, scenario: str, sim_task: SimTask, failures: bool) -> None:
    """One-line errors for a request the simulator cannot write: format, count, scenario."""
    if fmt not in FORMATS:
        raise InputError(f"unknown format {fmt!r} (known: {', '.join(FORMATS)})", field="format")
    if n_trials < 1:
        raise InputError(f"need at least one trial, got {n_trials}", field="trials")
    get_scenario(scenario)
    check_request(sim_task, scenario, failures)


def _write_trial(trial: Trial, out: Path, name: str, fmt: DatasetFormat, sim_task: SimTask) -> Path:
    """Write one trial: a rosbag2 file, or a HIRO folder with its meta.json."""
    if fmt == "bag":
        path = out / f"{name}.mcap"
        write_trial_bag(trial, path)
        return path
    path = write_trial(trial, out / name, task=sim_task.task)
    (path / "meta.json").write_text(json.dumps(trial.metadata, indent=1) + "\n")
    return path


@dataclass(frozen=True)
class _Unit:
    """One trial of a set to simulate: its index, seed, failure and session (None: no sessions)."""

    index: int
    seed: int
    failure: FailureType | None
    session: SessionSensor | None


def _simulate_one(
    simulate: TrialSimulator,
    out: Path,
    fmt: DatasetFormat,
    sim_task: SimTask,
    scenario: ScenarioName,
    unit: _Unit,
) -> tuple[Path, dict[str, object]]:
    """Simulate and write one trial (on any worker); its path and its sim_meta.json entry."""
    name = trial_name(scenario, unit.index, unit.failure, sim_task.label)
    trial = simulate(unit.seed, unit.failure, name)
    if unit.session is not None:
        trial = in_session(trial, unit.session)
    return _write_trial(trial, out, name, fmt, sim_task), _index_entry(name, trial)


def _index_entry(name: str, trial: Trial) -> dict[str, object]:
    """A trial's entry in sim_meta.json: name, outcome, switch times, end and its metadata."""
    return {
        "name": name,
        "outcome": trial.outcome,
        "state_times": list(trial.state_times),
        "end_time": trial.end_time,
        **trial.metadata,
    }


def write_dataset(
    out_dir: Path | str,
    n_trials: int,
    *,
    scenario: ScenarioName = "one-arm",
    seed: int = 0,
    failures: bool = False,
    rate_hz: float | None = None,
    fmt: DatasetFormat = "hiro",
    progress: Callable[[int], object] | None = None,
    config: TaskConfig | None = None,
    task: SimTaskName = "snap-assembly",
    sessions: int = 1,
    jobs: int = 1,
) -> list[Path]:
    """Simulate `n_trials` trials of `task` into `out_dir`; returns the written trial folders (or
    bag files). `rate_hz` None is the task's sensor rate (config sensor.rate_hz); `sessions` > 1
    splits the trials into recording sessions with a sensor bias and drift each (sim/sessions.py);
    `progress` is called with 1 after each trial. `jobs`: joblib workers (fleet.parallel_map);
    each trial has its own seed, so the set is the same whatever the count."""
    sim_task = get_sim_task(task)
    _check_set(fmt, n_trials, scenario, sim_task, failures)
    config = config or sim_task.load_config(None)
    rate = config.sensor.rate_hz if rate_hz is None else rate_hz
    simulate = trial_simulator(sim_task, config, scenario, rate)
    days = draw_sessions(sessions, seed, config.sensor) if sessions > 1 else []
    out = Path(out_dir)
    _clear_previous_set(out)
    out.mkdir(parents=True, exist_ok=True)
    types = task_failure_classes(config)
    plan = trial_plan(n_trials, seed, failures, types)
    units = [
        _Unit(i, trial_seed, failure, days[session_of(i, n_trials, sessions)] if days else None)
        for i, (trial_seed, failure) in enumerate(plan)
    ]
    one = functools.partial(_simulate_one, simulate, out, fmt, sim_task, scenario)
    done = parallel_map(one, units, jobs, progress)
    written = [path for path, _ in done]
    index = [entry for _, entry in done]
    meta: dict[str, object] = {"task": sim_task.name, "scenario": scenario, "seed": seed}
    meta.update({"rate_hz": rate, "format": fmt, "trials": index})
    (out / "sim_meta.json").write_text(json.dumps(meta, indent=1) + "\n")
    return written

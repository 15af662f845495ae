"""The simulated tasks `rcbht sim --task` chooses from: each one's sub-tasks, configuration file,
scenarios, failure support and trial simulator."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, get_args

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.sim.config import FailureType, SimConfig, load_sim_config
from rcbht_introspection.sim.failures import failure_classes
from rcbht_introspection.sim.peg_config import PegConfig, load_peg_config
from rcbht_introspection.sim.peg_controller import PEG_TASK
from rcbht_introspection.sim.peg_simulate import simulate_peg_trial
from rcbht_introspection.sim.scenario import ScenarioName
from rcbht_introspection.sim.simulate import simulate_trial
from rcbht_introspection.task import HIRO_TASK, Task

SimTaskName = Literal["snap-assembly", "peg-in-hole"]
SIM_TASKS: tuple[str, ...] = get_args(SimTaskName)
TaskConfig = SimConfig | PegConfig
"""The configuration of either task (config/sim/snap.yaml or config/sim/peg.yaml)."""
TrialSimulator = Callable[[int, FailureType | None, str], Trial]
"""(trial seed, failure type or None, trial name) -> the simulated trial."""


@dataclass(frozen=True)
class SimTask:
    """A simulated task: its sub-tasks, config file, scenarios and whether it has failure trials."""

    name: SimTaskName
    task: Task
    config_file: str
    load_config: Callable[[Path | str | None], TaskConfig]
    """Loader of the task's config file (or of another file given as `path`)."""
    scenarios: tuple[ScenarioName, ...]
    failures: bool
    label: str | None
    """Trial folder label (SIM-<label>-S-01); None: the scenario's (ONE or TWO)."""


SIM_TASK_TABLE: dict[str, SimTask] = {  # keyed by SimTaskName; looked up by any user string
    "snap-assembly": SimTask(
        "snap-assembly",
        HIRO_TASK,
        "sim/snap.yaml",
        load_sim_config,
        ("one-arm", "two-arm"),
        True,
        None,
    ),
    "peg-in-hole": SimTask(
        "peg-in-hole", PEG_TASK, "sim/peg.yaml", load_peg_config, ("one-arm",), True, "PEG"
    ),
}


def sim_task_of(config: TaskConfig) -> SimTask:
    """The task a configuration configures."""
    return SIM_TASK_TABLE["peg-in-hole" if isinstance(config, PegConfig) else "snap-assembly"]


def task_failure_classes(config: TaskConfig) -> tuple[str, ...]:
    """The failure classes a task's config draws (each snap deviation class is one)."""
    if isinstance(config, PegConfig):
        return config.failures.types
    return failure_classes(config.failures)


def get_sim_task(name: str) -> SimTask:
    """The named simulated task, or a one-line error listing the known ones."""
    try:
        return SIM_TASK_TABLE[name]
    except KeyError:
        raise InputError(
            f"unknown task {name!r} (known: {', '.join(SIM_TASKS)})", field="task"
        ) from None


def load_task_config(name: str, path: Path | str | None = None) -> TaskConfig:
    """The task's configuration: `path`, else its file in config/."""
    return get_sim_task(name).load_config(path)


def check_request(sim_task: SimTask, scenario: str, failures: bool) -> None:
    """One-line errors for a scenario or failure trials the task does not have."""
    if scenario not in sim_task.scenarios:
        raise InputError(
            f"task {sim_task.name} has no scenario {scenario!r} "
            f"(known: {', '.join(sim_task.scenarios)})",
            field="scenario",
        )
    if failures and not sim_task.failures:
        raise InputError(f"task {sim_task.name} simulates successes only", field="failures")


def trial_simulator(
    sim_task: SimTask, config: TaskConfig, scenario: ScenarioName, rate_hz: float
) -> TrialSimulator:
    """The function that simulates one trial of the task with this config, scenario and rate."""
    if isinstance(config, PegConfig) and sim_task.name == "peg-in-hole":
        peg = config
        return lambda seed, failure, name: simulate_peg_trial(peg, seed, rate_hz, name, failure)
    if isinstance(config, SimConfig) and sim_task.name == "snap-assembly":
        snap = config
        return lambda seed, failure, name: simulate_trial(
            snap, seed, scenario, failure, rate_hz, name=name
        )
    raise InputError(
        f"a {type(config).__name__} does not configure task {sim_task.name} "
        f"(its file: config/{sim_task.config_file})",
        field="config",
    )

"""A recorded or simulated trial: time, wrench per arm, sub-task start times."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rcbht_introspection.errors import InputError
from rcbht_introspection.task import HIRO_TASK
from rcbht_introspection.taxonomy.words import AXES as AXES  # re-exported

SUBTASKS: tuple[str, ...] = HIRO_TASK.subtasks
"""The HIRO snap assembly's sub-tasks: the names of a trial whose phases are not given."""


@dataclass(frozen=True)
class Trial:
    """One trial; `wrench[arm]` is (N, 6) in AXES order, `time` is (N,) seconds, increasing."""

    name: str
    time: np.ndarray
    wrench: dict[str, np.ndarray]
    state_times: tuple[float, ...] = ()
    """Start times of the trial's phases, non-decreasing (HIRO: the first is 0.0)."""
    outcome: str = "success"
    """'success', or the failure type of a failed trial."""
    metadata: dict[str, object] = field(default_factory=dict)
    phases: tuple[str, ...] = ()
    """Sub-task started at each state time; empty: the HIRO names in order (SUBTASKS)."""

    @property
    def phase_names(self) -> tuple[str, ...]:
        """The sub-task name of each state time."""
        if self.phases:
            return self.phases
        return SUBTASKS[: len(self.state_times)]

    @property
    def arms(self) -> tuple[str, ...]:
        """Arm names present, e.g. ('R',) or ('L', 'R')."""
        return tuple(sorted(self.wrench))

    @property
    def end_time(self) -> float:
        return float(self.time[-1]) if len(self.time) else 0.0

    def subtask_bounds(self) -> list[tuple[str, float, float]]:
        """(sub-task, start, end) for every sub-task with a start time; the last ends at end_time."""
        names = self.phase_names
        starts = list(self.state_times)[: len(names)]
        if not starts:
            return []
        ends = [*starts[1:], self.end_time]
        return list(zip(names, starts, ends, strict=True))


def check_phases(trial: Trial, path: Path | str | None = None) -> None:
    """One named error when the trial's phases cannot be cut into sub-tasks.

    Without phase names only the first len(SUBTASKS) state times have a name (HIRO's files hold
    no more); given names must match the state times one to one; times must not decrease and
    must not come after the last sample (that would be a negative-duration sub-task)."""
    if trial.phases and len(trial.phases) != len(trial.state_times):
        raise InputError(
            f"{len(trial.phases)} phase names for {len(trial.state_times)} state times",
            path,
            field="phases",
        )
    times = list(trial.state_times)
    for i in range(1, len(times)):
        if times[i] < times[i - 1]:
            raise InputError(
                f"state time {times[i]} s comes before the previous one ({times[i - 1]} s)",
                path,
                field="state time",
            )
    if times and len(trial.time) and times[-1] > trial.end_time:
        name = trial.phase_names[min(len(times), len(trial.phase_names)) - 1]
        raise InputError(
            f"sub-task {name!r} starts at {times[-1]} s, after the last sample ({trial.end_time} s)",
            path,
            field="state time",
        )

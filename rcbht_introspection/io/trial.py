"""A recorded or simulated trial: time, wrench per arm, sub-task start times."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rcbht_introspection.taxonomy.words import AXES  # noqa: F401  (re-exported)

SUBTASKS: tuple[str, ...] = ("approach", "rotation", "insertion", "mating")


@dataclass(frozen=True)
class Trial:
    """One trial; `wrench[arm]` is (N, 6) in AXES order, `time` is (N,) seconds, increasing."""

    name: str
    time: np.ndarray
    wrench: dict[str, np.ndarray]
    state_times: tuple[float, ...] = ()
    """Start times of the sub-tasks in SUBTASKS order (the first is 0.0); may be shorter."""
    outcome: str = "success"
    """'success', or the failure type of a failed trial."""
    metadata: dict[str, object] = field(default_factory=dict)

    @property
    def arms(self) -> tuple[str, ...]:
        """Arm names present, e.g. ('R',) or ('L', 'R')."""
        return tuple(sorted(self.wrench))

    @property
    def end_time(self) -> float:
        return float(self.time[-1]) if len(self.time) else 0.0

    def subtask_bounds(self) -> list[tuple[str, float, float]]:
        """(sub-task, start, end) for every sub-task with a start time; the last ends at end_time."""
        starts = list(self.state_times)[: len(SUBTASKS)]
        if not starts:
            return []
        ends = [*starts[1:], self.end_time]
        return [(SUBTASKS[i], s, e) for i, (s, e) in enumerate(zip(starts, ends, strict=True))]

"""Checks of a wrench recording before the RCBHT: repeated time stamps and a frozen sensor.

The same rules run on a whole recording (trial files and bags: `resolve_repeated_stamps`,
`frozen_runs`) and sample by sample in segmenter_node (`FrozenWatch`, `spread_stamp`), so a trial
read from files and the same trial streamed live give the same samples and the same findings.

* A repeated stamp: a sample stamped like the previous one. With the same six values it is a
  re-sent message (`duplicate_sample`) and always dropped. Otherwise the policy decides:
  `reject` drops it (`repeated_stamp`); `spread` places the samples sharing a stamp evenly
  between it and the next later stamp (`respaced_stamps`); with no later stamp they are dropped.
* A frozen sensor: at least `min_samples` consecutive samples with the same six values that
  span at least `min_s` seconds (a real force/torque sensor is never that still). Detection only:
  the samples are kept.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from rcbht_introspection.io.trial import Trial

RepeatedPolicy = Literal["reject", "spread"]
"""What happens to a sample stamped like the previous one (with other values)."""
REPEAT_COUNTERS: tuple[str, ...] = ("duplicate_sample", "repeated_stamp", "respaced_stamps")
"""Counts of `resolve_repeated_stamps`: dropped re-sent messages, dropped and moved samples."""


def spread_stamp(previous: int | float, following: int | float, i: int, k: int) -> int | float:
    """Stamp of the i-th (1..k) of k samples that shared `previous`, evenly up to `following`;
    integer stamps (ns) stay integers."""
    if isinstance(previous, (int, np.integer)) and isinstance(following, (int, np.integer)):
        return int(previous) + (int(following) - int(previous)) * i // (k + 1)
    return float(previous) + (float(following) - float(previous)) * i / (k + 1)


def resolve_repeated_stamps(
    time: np.ndarray, wrench: np.ndarray, policy: RepeatedPolicy
) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """(time, wrench, counts) with no two samples sharing a stamp, by `policy` (module docstring).

    `time` must not decrease; integer stamps (ns) are spread in integers, as the live node does.
    """
    counts = dict.fromkeys(REPEAT_COUNTERS, 0)
    time = np.asarray(time)
    wrench = np.asarray(wrench, dtype=np.float64)
    same = np.diff(time) == 0
    if not same.any():
        return time, wrench, counts
    keep_t: list[int | float] = []
    keep_rows: list[int] = []
    n = len(time)
    start = 0
    while start < n:
        stop = start + 1
        while stop < n and time[stop] == time[start]:
            stop += 1
        taken = [start]
        for j in range(start + 1, stop):
            if np.array_equal(wrench[j], wrench[taken[-1]]):
                counts["duplicate_sample"] += 1
            else:
                taken.append(j)
        keep_t.append(time[start].item())
        keep_rows.append(start)
        extra = taken[1:]
        if extra and policy == "spread" and stop < n:
            following = time[stop].item()
            for i, j in enumerate(extra, start=1):
                keep_t.append(spread_stamp(time[start].item(), following, i, len(extra)))
                keep_rows.append(j)
            counts["respaced_stamps"] += len(extra)
        else:
            counts["repeated_stamp"] += len(extra)
        start = stop
    return np.asarray(keep_t, dtype=time.dtype), wrench[keep_rows], counts


@dataclass(frozen=True)
class FrozenRun:
    """Consecutive samples with the same six values: rows [start, stop) from `t0` to `t1` (s)."""

    start: int
    stop: int
    t0: float
    t1: float
    values: tuple[float, ...]

    @property
    def samples(self) -> int:
        return self.stop - self.start

    def describe(self, arm: str, n_total: int | None = None) -> str:
        """One line: which arm, how long, from when, which values."""
        share = f", {100 * self.samples / n_total:.0f} % of the samples" if n_total else ""
        values = ", ".join(f"{v:.4g}" for v in self.values)
        return (
            f"arm {arm}: wrench frozen: the same values ({values}) for {self.samples} samples "
            f"({self.t1 - self.t0:.2f} s{share}) from {self.t0:.3f} s"
        )


def frozen_runs(
    time: np.ndarray, wrench: np.ndarray, min_samples: int, min_s: float
) -> list[FrozenRun]:
    """The frozen runs of a recording (`time` in seconds); none when `min_samples` is 0."""
    wrench = np.asarray(wrench, dtype=np.float64)
    time = np.asarray(time, dtype=np.float64)
    if min_samples <= 0 or len(wrench) < max(min_samples, 1):
        return []
    same = np.all(wrench[1:] == wrench[:-1], axis=1)
    # run boundaries: a row starts a run unless it equals the row before it
    starts = np.flatnonzero(np.concatenate(([True], ~same)))
    stops = np.append(starts[1:], len(wrench))
    runs = []
    for a, b in zip(starts.tolist(), stops.tolist(), strict=True):
        if b - a >= min_samples and time[b - 1] - time[a] >= min_s:
            values = tuple(float(v) for v in wrench[a])
            runs.append(FrozenRun(a, b, float(time[a]), float(time[b - 1]), values))
    return runs


class FrozenWatch:
    """`frozen_runs` sample by sample for one arm: is the sensor frozen now, and how often was it."""

    def __init__(self, min_samples: int, min_s: float) -> None:
        self.min_samples = min_samples
        self.min_ns = round(min_s * 1e9)
        self.last: tuple[float, ...] | None = None
        self.run = 0
        self.run_start_ns = 0
        self.last_ns = 0
        self.frozen = False
        self.episodes = 0
        """Frozen runs seen (a run counts once, when it becomes long enough)."""
        self.frozen_samples = 0
        """Samples that belong to frozen runs (the whole run, from its first sample)."""

    def push(self, stamp_ns: int, values: tuple[float, ...]) -> bool:
        """Note one accepted sample; True when a frozen run starts being one at this sample."""
        self.last_ns = stamp_ns
        if values == self.last:
            self.run += 1
            if self.frozen:
                self.frozen_samples += 1
                return False
        else:
            self.last, self.run, self.run_start_ns, self.frozen = values, 1, stamp_ns, False
        if (
            self.min_samples > 0
            and self.run >= self.min_samples
            and stamp_ns - self.run_start_ns >= self.min_ns
        ):
            self.frozen = True
            self.episodes += 1
            self.frozen_samples += self.run
            return True
        return False

    def describe(self, arm: str) -> str:
        """One line about the current run of equal samples (while `frozen`: the frozen run)."""
        values = ", ".join(f"{v:.4g}" for v in self.last or ())
        seconds = (self.last_ns - self.run_start_ns) / 1e9
        return (
            f"arm {arm}: wrench frozen: the same values ({values}) for {self.run} samples "
            f"({seconds:.2f} s)"
        )


REPEAT_TEXT = {
    "duplicate_sample": "{} re-sent samples dropped (same stamp and values)",
    "repeated_stamp": "{} samples with a repeated stamp dropped",
    "respaced_stamps": "{} samples with a repeated stamp spread towards the next stamp",
}
REPEATED_METADATA = "repeated_stamps"
"""Trial.metadata key: per arm, the counts of `resolve_repeated_stamps` when a policy applied."""


def trial_findings(trial: Trial, min_samples: int, min_s: float) -> list[str]:
    """One line per problem of a trial's wrench: frozen runs, samples dropped or moved by the
    repeated-stamp policy it was read with (for the batch commands to print as warnings)."""
    lines = []
    repeated = trial.metadata.get(REPEATED_METADATA)
    for arm in trial.arms:
        counts = repeated.get(arm, {}) if isinstance(repeated, dict) else {}
        done = [REPEAT_TEXT[k].format(n) for k, n in counts.items() if n and k in REPEAT_TEXT]
        if done:
            lines.append(f"arm {arm}: repeated time stamps: {', '.join(done)}")
        for run in frozen_runs(trial.time, trial.wrench[arm], min_samples, min_s):
            lines.append(run.describe(arm, len(trial.time)))
    return lines

"""Causal raw-wrench features of a stream, on a tick grid (every `step_s`).

At tick g an arm's features use only samples stamped <= g: the mean of each axis over the last
`window_s`, that mean's change over the last `lag_s` and each axis's spread over the window (from
the stream's first tick while the stream is younger), and the jump: the largest departure of any
sample since the tick before from the mean of the samples of an earlier step (JUMP_STEPS back),
sample by sample at the sensor's rate. The change and the jump are what the detector reads: a
constant sensor bias, drift slower than `lag_s` and the load of the gripper cancel in them; the
change sees a contact that stays, the jump one that comes and goes within a tick or two, and the
departure (`SubtaskDeparture`, from the ticks' sub-tasks) one that keeps growing for seconds. The
same `ArmFeatures` object serves the live verifier (sample by sample) and the offline
evaluation (a whole trial fed through it), so both see identical numbers.
"""

from __future__ import annotations

import dataclasses
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rcbht_introspection.io.bags import trial_phase_events
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.verify.config import WRENCH_AXES, VerifyConfig

KINDS = ("mean", "change", "std", "jump")
"""Feature blocks of an arm, six axes each."""
PER_ARM = 6 * len(KINDS)
JUMP_STEPS = 2
"""A jump is measured from the mean of the samples this many steps back: a push that rises
over a tenth of a second counts in full, a single sample's noise is averaged out of the
reference."""


def kind_columns(kind: str, n_arms: int) -> np.ndarray:
    """Column indices of one feature kind for every arm."""
    k = KINDS.index(kind)
    return np.array([a * PER_ARM + k * 6 + x for a in range(n_arms) for x in range(6)], dtype=int)


def feature_names(arms: Sequence[str]) -> list[str]:
    """Names of the feature columns, arms in the given order."""
    return [f"{arm}.{k}.{a}" for arm in arms for k in KINDS for a in WRENCH_AXES]


def lag_ticks(config: VerifyConfig) -> int:
    """The change's lag in ticks (at least one)."""
    return max(1, round(config.lag_s / config.step_s))


class ArmFeatures:
    """One arm's wrench samples in, one feature row per passed tick out."""

    def __init__(self, config: VerifyConfig) -> None:
        self.config = config
        self.window: deque[tuple[float, np.ndarray]] = deque()
        self.sum = np.zeros(6)
        self.sumsq = np.zeros(6)
        self.next_tick = 0
        """Index of the next tick to emit (tick k is at k * step_s)."""
        self._means: deque[np.ndarray] = deque(maxlen=lag_ticks(config) + 1)
        self._last = np.zeros(PER_ARM)
        self._step_sum = np.zeros(6)
        self._step_n = 0
        """The samples since the last tick: their sum and count (the next reference)."""
        self._steps: deque[np.ndarray] = deque(maxlen=JUMP_STEPS)
        """The means of the samples of the last steps: the oldest is the jump's reference."""
        self._jump = np.zeros(6)
        """The largest departure from the reference of any sample since the last tick."""

    def push(self, t: float, wrench: np.ndarray) -> list[tuple[float, np.ndarray]]:
        """Add the sample at stream time t; returns (tick time, features) of every tick before t."""
        out = []
        step = self.config.step_s
        while self.next_tick * step < t:
            g = self.next_tick * step
            self.next_tick += 1
            out.append((g, self._row()))
        w = np.asarray(wrench, dtype=float)
        if self._steps:
            np.maximum(self._jump, np.abs(w - self._steps[0]), out=self._jump)
        self._step_sum += w
        self._step_n += 1
        self.window.append((t, w))
        self.sum += w
        self.sumsq += w * w
        while self.window and self.window[0][0] <= t - self.config.window_s:
            _, old = self.window.popleft()
            self.sum -= old
            self.sumsq -= old * old
        return out

    def flush(self) -> list[tuple[float, np.ndarray]]:
        """The stream ended: one last row at the last sample's time (when no tick fell on it)."""
        if not self.window:
            return []
        t = self.window[-1][0]
        if (self.next_tick - 1) * self.config.step_s >= t:
            return []
        self.next_tick = int(np.floor(t / self.config.step_s)) + 1
        return [(t, self._row())]

    def _row(self) -> np.ndarray:
        """The features of the next tick; an empty window (no sample for window_s, or none yet)
        holds the last row (zeros before the first sample), so every arm has a row per tick."""
        jump = self._jump
        if self._step_n:
            self._steps.append(self._step_sum / self._step_n)
        self._step_sum, self._step_n, self._jump = np.zeros(6), 0, np.zeros(6)
        if not self.window:
            return self._last.copy()
        mean = self.sum / len(self.window)
        std = np.sqrt(np.maximum(self.sumsq / len(self.window) - mean * mean, 0.0))
        self._means.append(mean)
        self._last = np.concatenate([mean, mean - self._means[0], std, jump])
        return self._last.copy()


@dataclass(frozen=True)
class TrialFeatures:
    """A trial's feature rows: tick times, commanded sub-task index and elapsed time per tick."""

    trial: str
    phases: tuple[str, ...]
    """The trial's sub-task names in order (the commanded phases)."""
    starts: np.ndarray
    """Start time of each phase (stream seconds)."""
    times: np.ndarray
    phase_index: np.ndarray
    """Index into `phases` of the sub-task running at each tick (-1 before the first)."""
    elapsed: np.ndarray
    features: np.ndarray
    end: float


def trial_features(trial: Trial, config: VerifyConfig, end_phase: str = "done") -> TrialFeatures:
    """Feed the trial through one ArmFeatures per arm as the verifier node is fed a replayed bag,
    arms in sorted order; each tick is placed in the sub-task running at it."""
    time = np.asarray(trial.time, dtype=float) - float(trial.time[0])
    events = [(t, n) for t, n in trial_phase_events(trial, end_phase) if n != end_phase]
    rows: dict[str, list[tuple[float, np.ndarray]]] = {}
    for arm in trial.arms:
        feats = ArmFeatures(config)
        wrench = np.asarray(trial.wrench[arm], dtype=float)
        arm_rows: list[tuple[float, np.ndarray]] = []
        for i in range(len(time)):
            arm_rows.extend(feats.push(float(time[i]), wrench[i]))
        arm_rows.extend(feats.flush())
        rows[arm] = arm_rows
    n = min(len(r) for r in rows.values())
    times = np.array([g for g, _ in rows[trial.arms[0]][:n]])
    features = np.hstack([np.array([f for _, f in rows[a][:n]]) for a in trial.arms])
    starts = np.array([t - float(trial.time[0]) for t, _ in events])
    names = tuple(n for _, n in events)
    idx = np.searchsorted(starts, times, side="right") - 1
    elapsed = (
        np.where(idx >= 0, times - starts[np.clip(idx, 0, None)], 0.0)
        if len(starts)
        else np.zeros(len(times))
    )
    return TrialFeatures(
        trial=trial.name,
        phases=names,
        starts=starts,
        times=times,
        phase_index=idx,
        elapsed=elapsed,
        features=features.reshape(len(times), -1),
        end=float(time[-1]),
    )


class SubtaskDeparture:
    """Each tick's mean wrench minus the mean of its sub-task's tick `lag` ticks after the
    sub-task's first (0 until then), ticks fed in order: a departure that keeps growing for
    seconds, of which the change over lag_s holds one step. The reference is the trial's own,
    so bias, load and the part's placement in this trial cancel."""

    def __init__(self, lag: int, n_arms: int) -> None:
        self.lag = lag
        self.columns = kind_columns("mean", n_arms)
        self.phase = -1
        self.count = 0
        self.reference: np.ndarray | None = None

    def row(self, phase_index: int, features: np.ndarray) -> np.ndarray:
        """`features` with its mean block replaced by the departure (the tick's sub-task index)."""
        if phase_index != self.phase:
            self.phase, self.count, self.reference = phase_index, 0, None
        if self.count == self.lag:
            self.reference = features[self.columns].copy()
        self.count += 1
        out = np.array(features, dtype=float)
        if self.reference is None:
            out[self.columns] = 0.0
        else:
            out[self.columns] -= self.reference
        return out


def departure_features(tf: TrialFeatures, lag: int) -> TrialFeatures:
    """tf with each row's mean block replaced by its departure, tick by tick as the live
    verifier computes it (`SubtaskDeparture`)."""
    departure = SubtaskDeparture(lag, tf.features.shape[1] // PER_ARM)
    rows = [departure.row(int(i), f) for i, f in zip(tf.phase_index, tf.features, strict=True)]
    return dataclasses.replace(tf, features=np.array(rows).reshape(tf.features.shape))

"""Causal raw-wrench features of the running sub-task, on a tick grid (every `step_s`).

At tick g the features of one arm use only samples stamped <= g and the sub-task events before
them: the mean and spread of each axis over the last `window_s`, the mean's change since the
first `baseline_s` of the running sub-task, and that change's running maximum and minimum in the
sub-task. The same `ArmFeatures` object serves the live verifier (sample by sample) and the
offline evaluation (a whole trial fed through it), so both see identical numbers.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rcbht_introspection.io.bags import trial_phase_events
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.verify.config import KINDS, WRENCH_AXES, VerifyConfig

PER_ARM = 36
"""Features per arm: window mean (6), window std (6), change since baseline (6), its max (6),
min (6), and the mean's ratios to the pressing force (6)."""
RATIO_MIN_FORCE = 1.0
"""|Fz| (N) below which the ratios are 0: in free motion they are noise over noise."""


def kind_columns(kinds: Sequence[str], n_arms: int) -> np.ndarray:
    """Column indices of the given feature kinds for every arm."""
    return np.array(
        [
            a * PER_ARM + KINDS.index(k) * 6 + x
            for a in range(n_arms)
            for k in KINDS
            if k in kinds
            for x in range(6)
        ],
        dtype=int,
    )


def scale_floors(config: VerifyConfig, n_columns: int) -> np.ndarray:
    """The smallest spread of each feature column: forces and moments have their own floor."""
    axis = np.arange(n_columns) % 6
    return np.where(axis < 3, config.scale_floor_force, config.scale_floor_torque)


def feature_names(arms: Sequence[str]) -> list[str]:
    """Names of the feature columns, arms in the given order."""
    return [f"{arm}.{k}.{a}" for arm in arms for k in KINDS for a in WRENCH_AXES]


def ratios(mean: np.ndarray) -> np.ndarray:
    """Fx/Fz, Fy/Fz, Fz, Mx/Fz, My/Fz, Mz/Fz of a mean wrench: where and how the part touches
    (the moment ratios are lever arms, m), independent of how hard it presses."""
    fz = mean[2]
    if abs(fz) < RATIO_MIN_FORCE:
        return np.array([0.0, 0.0, fz, 0.0, 0.0, 0.0])
    return np.array([mean[0] / fz, mean[1] / fz, fz, mean[3] / fz, mean[4] / fz, mean[5] / fz])


class ArmFeatures:
    """One arm's wrench samples in, one feature row per passed tick out."""

    def __init__(self, config: VerifyConfig) -> None:
        self.config = config
        self.window: deque[tuple[float, np.ndarray]] = deque()
        self.sum = np.zeros(6)
        self.sumsq = np.zeros(6)
        self.next_tick = 0
        """Index of the next tick to emit (tick k is at k * step_s)."""
        self.phase_start = -math.inf
        self._last = np.zeros(PER_ARM)
        self._base_sum = np.zeros(6)
        self._base_n = 0
        self._hi = np.full(6, -np.inf)
        self._lo = np.full(6, np.inf)

    def phase(self, t: float) -> None:
        """A sub-task starts at stream time t: baseline and extremes start again."""
        self.phase_start = t
        self._base_sum = np.zeros(6)
        self._base_n = 0
        self._hi = np.full(6, -np.inf)
        self._lo = np.full(6, np.inf)

    def push(self, t: float, wrench: np.ndarray) -> list[tuple[float, np.ndarray]]:
        """Add the sample at stream time t; returns (tick time, features) of every tick before t."""
        out = []
        step = self.config.step_s
        while self.next_tick * step < t:
            g = self.next_tick * step
            self.next_tick += 1
            out.append((g, self._row(g)))
        w = np.asarray(wrench, dtype=float)
        self.window.append((t, w))
        self.sum += w
        self.sumsq += w * w
        while self.window and self.window[0][0] <= t - self.config.window_s:
            _, old = self.window.popleft()
            self.sum -= old
            self.sumsq -= old * old
        if t >= self.phase_start and t <= self.phase_start + self.config.baseline_s:
            self._base_sum += w
            self._base_n += 1
        return out

    def flush(self) -> list[tuple[float, np.ndarray]]:
        """The stream ended: one last row at the last sample's time (when no tick fell on it)."""
        if not self.window:
            return []
        t = self.window[-1][0]
        if (self.next_tick - 1) * self.config.step_s >= t:
            return []
        self.next_tick = int(np.floor(t / self.config.step_s)) + 1
        return [(t, self._row(t))]

    def _row(self, g: float) -> np.ndarray:
        """The features at tick g; an empty window (no sample for window_s, or none yet) holds
        the last row (zeros before the first sample: the tared wrench), so every arm has a row
        for every tick."""
        n = len(self.window)
        if n == 0:
            return self._last.copy()
        mean = self.sum / n
        std = np.sqrt(np.maximum(self.sumsq / n - mean * mean, 0.0))
        base = self._base_sum / self._base_n if self._base_n else mean
        change = mean - base
        self._hi = np.maximum(self._hi, change)
        self._lo = np.minimum(self._lo, change)
        self._last = np.concatenate([mean, std, change, self._hi, self._lo, ratios(mean)])
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
    """Feed the trial through one ArmFeatures per arm as the verifier node is fed a replayed bag
    (the sub-task events applied before the next sample), arms in sorted order."""
    time = np.asarray(trial.time, dtype=float) - float(trial.time[0])
    events = [(t, n) for t, n in trial_phase_events(trial, end_phase) if n != end_phase]
    rows: dict[str, list[tuple[float, np.ndarray]]] = {}
    for arm in trial.arms:
        feats = ArmFeatures(config)
        wrench = np.asarray(trial.wrench[arm], dtype=float)
        ev = 0
        arm_rows: list[tuple[float, np.ndarray]] = []
        for i in range(len(time)):
            while ev < len(events) and events[ev][0] - float(trial.time[0]) <= time[i]:
                feats.phase(events[ev][0] - float(trial.time[0]))
                ev += 1
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

"""How far a running sub-task is from the successful trials: a nominal envelope of the features
per sub-task and elapsed time, and the nominal range of each sub-task's duration.

Both are fitted on successful trials only. `EnvelopeModel.z` gives each feature's signed distance
from the nominal median in nominal spreads; the novelty of a tick is the mean of its `top_k`
largest |z|. `TimingModel` scores a sub-task that has lasted longer than any nominal one, or that
ended sooner or later than the nominal range.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from rcbht_introspection.verify.config import VerifyConfig
from rcbht_introspection.verify.features import (
    PER_ARM,
    TrialFeatures,
    kind_columns,
    scale_floors,
)


def pool_ticks(
    trials: Sequence[TrialFeatures], phase_free: bool = False
) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The trials' ticks per sub-task in order of first appearance: (elapsed time, features,
    trial index). `phase_free`: one pool "all" of every tick after the first event, by time
    into the trial."""
    parts: dict[str, list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {}
    for j, tf in enumerate(trials):
        for i, name in enumerate(("all",) if phase_free else tf.phases):
            sel = tf.phase_index >= 0 if phase_free else tf.phase_index == i
            if np.any(sel):
                el = tf.times[sel] if phase_free else tf.elapsed[sel]
                parts.setdefault(name, []).append((el, tf.features[sel], np.full(len(el), j)))
    return {
        name: (
            np.concatenate([q[0] for q in part]),
            np.vstack([q[1] for q in part]),
            np.concatenate([q[2] for q in part]),
        )
        for name, part in parts.items()
    }


@dataclass
class EnvelopeModel:
    """Per sub-task: median and spread per bin of time into the sub-task; `phase_free`: one
    envelope over time into the trial (no state machine: the raw-wrench baseline)."""

    reads_wrench: ClassVar[bool] = True
    """A characteriser reading evidence through it may read the wrench's contact geometry."""
    phases: tuple[str, ...]
    median: list[np.ndarray]
    """Per phase, (bins, features)."""
    scale: list[np.ndarray]
    bin_s: float
    top_k: int
    phase_free: bool = False

    @classmethod
    def fit(
        cls, trials: Sequence[TrialFeatures], config: VerifyConfig, phase_free: bool = False
    ) -> EnvelopeModel:
        pools = pool_ticks(trials, phase_free)
        names = list(pools)
        bin_s = config.elapsed_bin_s
        medians, scales = [], []
        for name in names:
            elapsed, feats, _ = pools[name]
            phase_mad = 1.4826 * np.median(np.abs(feats - np.median(feats, axis=0)), axis=0)
            floor = np.maximum(scale_floors(config, feats.shape[1]), 0.25 * phase_mad)
            n_bins = int(np.ceil((elapsed.max() + 1e-9) / bin_s)) + 1
            med = np.empty((n_bins, feats.shape[1]))
            scale = np.empty_like(med)
            half = config.elapsed_tolerance_s + bin_s / 2
            for b in range(n_bins):
                centre = (b + 0.5) * bin_s
                near = np.abs(elapsed - centre) <= half
                if not np.any(near):
                    near = np.abs(elapsed - centre) <= np.min(np.abs(elapsed - centre)) + 1e-9
                part = feats[near]
                med[b] = np.median(part, axis=0)
                scale[b] = np.maximum(1.4826 * np.median(np.abs(part - med[b]), axis=0), floor)
            medians.append(med)
            scales.append(scale)
        return cls(tuple(names), medians, scales, bin_s, config.top_k, phase_free)

    def z(self, tf: TrialFeatures) -> np.ndarray:
        """(ticks, features) signed z of every tick; NaN rows for ticks of unknown sub-tasks."""
        out = np.full(tf.features.shape, np.nan)
        for t in range(len(tf.times)):
            elapsed = tf.times[t] if self.phase_free else tf.elapsed[t]
            out[t] = self.z_row(self._phase_name(tf, t), float(elapsed), tf.features[t])
        return out

    def _phase_name(self, tf: TrialFeatures, tick: int) -> str:
        i = int(tf.phase_index[tick])
        if i < 0:
            return ""
        return "all" if self.phase_free else tf.phases[i]

    def z_row(self, phase: str, elapsed: float, features: np.ndarray) -> np.ndarray:
        """Signed z of one tick's features; NaN when the sub-task has no envelope."""
        if phase not in self.phases:
            return np.full(len(features), np.nan)
        p = self.phases.index(phase)
        b = min(int(elapsed / self.bin_s), len(self.median[p]) - 1)
        return (features - self.median[p][b]) / self.scale[p][b]

    def score_z(self, z: np.ndarray) -> np.ndarray:
        """Novelty per tick: the mean of the top_k largest |z| (NaN rows: +inf, an unknown sub-task)."""
        a = np.abs(np.atleast_2d(z))
        k = min(self.top_k, a.shape[1])
        top = -np.sort(-np.nan_to_num(a, nan=np.inf), axis=1)[:, :k]
        return top.mean(axis=1)


@dataclass
class TimingModel:
    """Nominal duration range of each sub-task, with a spread to score excursions in."""

    reads_wrench: ClassVar[bool] = False
    """The timing baseline's characteriser reads durations only, no contact geometry."""
    phases: tuple[str, ...]
    low: np.ndarray
    high: np.ndarray
    scale: np.ndarray

    @classmethod
    def fit(cls, trials: Sequence[TrialFeatures], config: VerifyConfig) -> TimingModel:
        durations: dict[str, list[float]] = {}
        for tf in trials:
            if not tf.phases:
                continue
            ends = [*tf.starts[1:], tf.end]
            for name, s, e in zip(tf.phases, tf.starts, ends, strict=True):
                durations.setdefault(name, []).append(float(e - s))
        names = tuple(durations)
        d = [np.asarray(durations[n]) for n in names]
        return cls(
            names,
            np.array([x.min() for x in d]),
            np.array([x.max() for x in d]),
            np.array([max(float(x.std()), config.step_s) for x in d]),
        )

    def running(self, phase: str, elapsed: float) -> float:
        """Score of a sub-task still running after `elapsed` s (>0 once past the nominal longest)."""
        if phase not in self.phases:
            return np.inf
        p = self.phases.index(phase)
        return max(0.0, (elapsed - self.high[p]) / self.scale[p])

    def ended(self, phase: str, duration: float) -> float:
        """Score of a sub-task that ended after `duration` s (>0 outside the nominal range)."""
        if phase not in self.phases:
            return np.inf
        p = self.phases.index(phase)
        return max(
            0.0, (self.low[p] - duration) / self.scale[p], (duration - self.high[p]) / self.scale[p]
        )

    def z(self, tf: TrialFeatures) -> np.ndarray:
        """(ticks, sub-tasks) signed duration so far of each nominal sub-task, from the middle of
        its nominal range in spreads (0 before it starts): the timing view of a trial."""
        out = np.zeros((len(tf.times), len(self.phases)))
        mid = (self.low + self.high) / 2
        for t in range(len(tf.times)):
            for i in range(int(tf.phase_index[t]) + 1):
                if tf.phases[i] in self.phases:
                    p = self.phases.index(tf.phases[i])
                    end = tf.starts[i + 1] if i + 1 < len(tf.starts) else tf.times[t]
                    out[t, p] = (
                        min(float(end), float(tf.times[t])) - tf.starts[i] - mid[p]
                    ) / self.scale[p]
        return out

    def scores(self, tf: TrialFeatures) -> np.ndarray:
        """Timing score per tick: the running sub-task's overrun, or the last ended one's excursion."""
        out = np.zeros(len(tf.times))
        for t in range(len(tf.times)):
            i = int(tf.phase_index[t])
            if i < 0:
                continue
            s = self.running(tf.phases[i], float(tf.elapsed[t]))
            if i > 0:
                s = max(s, self.ended(tf.phases[i - 1], float(tf.starts[i] - tf.starts[i - 1])))
            if t == len(tf.times) - 1 and i >= 0:  # the trial ended: so did its last sub-task
                s = max(s, self.ended(tf.phases[i], tf.end - float(tf.starts[i])))
            out[t] = s
        return out


@dataclass
class NeighbourModel:
    """The successful trials' ticks per sub-task; a tick's novelty is its distance to the
    `k`-th nearest successful trial among ticks of the same sub-task at a similar elapsed time
    (within max(tolerance, relative * elapsed)): "did any success look like this, about now?".
    Distances are root-mean-square over features in units of each feature's spread among those
    successes' ticks at that elapsed time (one spread per `bin_s`), so the tight first contact
    and the loose end of a sub-task are each measured by their own variation. `phase_free`: one
    pool over time into the trial (the raw-wrench baseline)."""

    phases: tuple[str, ...]
    elapsed: list[np.ndarray]
    """Per phase, the pooled ticks' elapsed times, sorted."""
    points: list[np.ndarray]
    """Per phase, (ticks, features) in the same order."""
    trial_ids: list[np.ndarray]
    scale: list[np.ndarray]
    """Per phase, (bins, features): the spread of each feature around each bin's elapsed time."""
    bin_s: float
    n_trials: int
    tolerance_s: float
    relative: float
    k: int
    columns: np.ndarray
    """The feature columns compared (config.novelty_features of every arm)."""
    phase_free: bool = False

    def window(self, p: int, elapsed: float) -> tuple[int, int]:
        """Index range of phase p's ticks within the tolerance of `elapsed`."""
        el = self.elapsed[p]
        tol = max(self.tolerance_s, self.relative * elapsed)
        lo = int(np.searchsorted(el, elapsed - tol, side="left"))
        hi = int(np.searchsorted(el, elapsed + tol, side="right"))
        if hi <= lo:  # beyond every success's elapsed time: compare with their last ticks
            lo, hi = max(len(el) - 1 - int(self.n_trials), 0), len(el)
        return lo, hi

    @classmethod
    def fit(
        cls,
        trials: Sequence[TrialFeatures],
        config: VerifyConfig,
        phase_free: bool = False,
    ) -> NeighbourModel:
        n_arms = trials[0].features.shape[1] // PER_ARM if trials else 1
        columns = kind_columns(config.novelty_features, n_arms)
        floors = scale_floors(config, n_arms * PER_ARM)[columns]
        pools = pool_ticks(trials, phase_free)
        names = list(pools)
        model = cls(
            tuple(names),
            [],
            [],
            [],
            [],
            config.elapsed_bin_s,
            len(trials),
            config.elapsed_tolerance_s,
            config.elapsed_relative,
            config.neighbours,
            columns,
            phase_free,
        )
        for p, name in enumerate(names):
            el, feats, ids = pools[name]
            order = np.argsort(el, kind="stable")
            model.elapsed.append(el[order])
            model.points.append(feats[order][:, columns])
            model.trial_ids.append(ids[order])
            n_bins = int(np.ceil((el.max() + 1e-9) / model.bin_s)) + 1
            scale = np.empty((n_bins, len(columns)))
            for b in range(n_bins):
                lo, hi = model.window(p, (b + 0.5) * model.bin_s)
                scale[b] = np.maximum(model.points[p][lo:hi].std(axis=0), floors)
            model.scale.append(scale)
        return model

    def score_row(self, phase: str, elapsed: float, features: np.ndarray) -> float:
        """Novelty of one tick (inf for a sub-task no success had)."""
        if phase not in self.phases:
            return float("inf")
        p = self.phases.index(phase)
        lo, hi = self.window(p, elapsed)
        scale = self.scale[p][min(int(elapsed / self.bin_s), len(self.scale[p]) - 1)]
        diff = (self.points[p][lo:hi] - features[self.columns]) / scale
        dist = np.sqrt(np.mean(diff * diff, axis=1))
        best = np.full(self.n_trials, np.inf)
        np.minimum.at(best, self.trial_ids[p][lo:hi], dist)
        k = min(self.k, int(np.sum(np.isfinite(best))))
        if k < 1:
            return float("inf")
        return float(np.partition(best, k - 1)[k - 1])

    def scores(self, tf: TrialFeatures) -> np.ndarray:
        """Novelty per tick (0 before the first sub-task)."""
        out = np.zeros(len(tf.times))
        for t in range(len(tf.times)):
            i = int(tf.phase_index[t])
            if i < 0:
                continue
            name = "all" if self.phase_free else tf.phases[i]
            elapsed = float(tf.times[t] if self.phase_free else tf.elapsed[t])
            out[t] = self.score_row(name, elapsed, tf.features[t])
        return out

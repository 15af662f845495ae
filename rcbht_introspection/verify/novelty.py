"""How far a running sub-task is from the successful trials: the distance of a tick to the
nearest success at the same time into the same sub-task, the nominal range of each sub-task's
duration, and the nominal mean wrench along each sub-task (what the characteriser compares the
wrench before onset with).

All are fitted on successful trials only. `TimingModel` scores a sub-task that has lasted longer
than any nominal one, or that ended sooner or later than the nominal range.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rcbht_introspection.verify.config import VerifyConfig
from rcbht_introspection.verify.features import PER_ARM, TrialFeatures, kind_columns

SCALE_FLOOR_FORCE = 0.02
"""Smallest spread of a force feature (N): sensor noise, never zero."""
SCALE_FLOOR_TORQUE = 0.001
"""... of a moment feature (N m)."""
ELAPSED_RELATIVE = 0.25
"""Late in a long sub-task the comparison window widens to this share of the elapsed time."""
BIN_S = 0.1
"""The spreads and the nominal mean are kept per BIN_S of time into the sub-task."""


def scale_floors(n_columns: int) -> np.ndarray:
    """The smallest spread of each column of a block of wrench axes (forces, then moments)."""
    axis = np.arange(n_columns) % 6
    return np.where(axis < 3, SCALE_FLOOR_FORCE, SCALE_FLOOR_TORQUE)


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
class TimingModel:
    """Nominal duration range of each sub-task, with a spread to score excursions in."""

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
        score: float = max(0.0, (elapsed - self.high[p]) / self.scale[p])
        return score

    def ended(self, phase: str, duration: float) -> float:
        """Score of a sub-task that ended after `duration` s (>0 outside the nominal range)."""
        if phase not in self.phases:
            return np.inf
        p = self.phases.index(phase)
        score: float = max(
            0.0, (self.low[p] - duration) / self.scale[p], (duration - self.high[p]) / self.scale[p]
        )
        return score

    def z_row(self, names: Sequence[str], starts: Sequence[float], t: float) -> np.ndarray:
        """Signed duration so far of each nominal sub-task at stream time t, from the middle of
        its nominal range in spreads (0 before it starts), given the sub-tasks started so far
        (`names` at `starts`): the timing view of a tick."""
        out = np.zeros(len(self.phases))
        mid = (self.low + self.high) / 2
        for i, name in enumerate(names):
            if name in self.phases and starts[i] <= t:
                p = self.phases.index(name)
                end = min(starts[i + 1] if i + 1 < len(starts) else t, t)
                out[p] = (end - starts[i] - mid[p]) / self.scale[p]
        return out

    def z(self, tf: TrialFeatures) -> np.ndarray:
        """(ticks, sub-tasks) `z_row` of every tick of a trial."""
        out = np.zeros((len(tf.times), len(self.phases)))
        for t in range(len(tf.times)):
            n = int(tf.phase_index[t]) + 1
            out[t] = self.z_row(tf.phases[:n], list(tf.starts[:n]), float(tf.times[t]))
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
    nearest successful trial among ticks of the same sub-task at a similar elapsed time
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
    scale: list[np.ndarray]
    """Per phase, (bins, features): the spread of each feature around each bin's elapsed time."""
    bin_s: float
    n_trials: int
    tolerance_s: float
    relative: float
    columns: np.ndarray
    """The feature columns compared (one kind of every arm)."""
    phase_free: bool = False
    largest: bool = False
    """Distances by the largest feature difference instead of the root-mean-square: a jump on
    one axis counts in full, not diluted by the quiet others (the `jump` features)."""

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
        kind: str = "change",
        largest: bool = False,
    ) -> NeighbourModel:
        """`kind`: the feature block compared (the verifier's change; the raw-wrench baseline's
        mean); `largest`: distances by the largest difference."""
        n_arms = trials[0].features.shape[1] // PER_ARM if trials else 1
        columns = kind_columns(kind, n_arms)
        floors = scale_floors(len(columns))
        pools = pool_ticks(trials, phase_free)
        names = list(pools)
        model = cls(
            tuple(names),
            [],
            [],
            [],
            BIN_S,
            len(trials),
            config.elapsed_tolerance_s,
            ELAPSED_RELATIVE,
            columns,
            phase_free,
            largest,
        )
        for p, name in enumerate(names):
            el, feats, _ = pools[name]
            order = np.argsort(el, kind="stable")
            model.elapsed.append(el[order])
            model.points.append(feats[order][:, columns])
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
        dist = np.abs(diff).max(axis=1) if self.largest else np.sqrt(np.mean(diff * diff, axis=1))
        return float(dist.min()) if len(dist) else float("inf")

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


@dataclass
class NominalLevel:
    """Per sub-task, the successes' median mean wrench per BIN_S of time into it: what the
    characteriser compares a failure's wrench just before onset with."""

    phases: tuple[str, ...]
    median: list[np.ndarray]
    """Per phase, (bins, 6 * arms)."""

    @classmethod
    def fit(cls, trials: Sequence[TrialFeatures]) -> NominalLevel:
        n_arms = trials[0].features.shape[1] // PER_ARM if trials else 1
        columns = kind_columns("mean", n_arms)
        pools = pool_ticks(trials)
        medians = []
        for elapsed, feats, _ in pools.values():
            bins = np.minimum((elapsed / BIN_S).astype(int), int(elapsed.max() / BIN_S))
            med = np.zeros((int(bins.max()) + 1, len(columns)))
            for b in range(len(med)):  # a bin no tick fell in keeps the one before it
                med[b] = (
                    np.median(feats[bins == b][:, columns], axis=0)
                    if np.any(bins == b)
                    else med[b - 1]
                )
            medians.append(med)
        return cls(tuple(pools), medians)

    def at(self, phase: str, elapsed: float) -> np.ndarray | None:
        """The nominal mean wrench at `elapsed` s into `phase` (None: no success had it)."""
        if phase not in self.phases:
            return None
        med = self.median[self.phases.index(phase)]
        nominal: np.ndarray = med[min(max(int(elapsed / BIN_S), 0), len(med) - 1)]
        return nominal

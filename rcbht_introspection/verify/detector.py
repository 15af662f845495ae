"""Failure detection: per-tick signals, thresholds calibrated on held-out successes, one alarm.

Signals (each a score per tick, higher = less nominal):
* `wrench`: distance to the nearest successful trials at the same sub-task and elapsed time
  (novelty.NeighbourModel);
* `timing`: a sub-task running longer, or ending sooner or later, than any nominal one;
* `wrench_global`: the same distance by time into the trial (the raw-wrench baseline: no state
  machine).
Each signal has a threshold per sub-task and span of time into it (threshold_segments_s: the
first contact of a sub-task varies less than its end). Calibration scores successes held out by
cross-fitting: each (signal, sub-task, span) maximum is divided by the upper quartile of its held-out maxima, and the
run's largest such ratio is its combined score; the thresholds are those quartiles times the
conformal (1 - false_alarm_rate) quantile of the combined scores, so the alarm - the first tick
at which any signal exceeds its threshold - fires on at most about `false_alarm_rate` of nominal
runs (1 / (n + 1) with n successes when n is too small for the quantile: the largest is used).
A success whose largest wrench ratio (timing aside) lies beyond the far-out fence of all
successes' (nominal_fence_iqr) is left out of the models and the calibration, and named in
`left_out`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from rcbht_introspection.verify.config import VerifyConfig
from rcbht_introspection.verify.features import TrialFeatures
from rcbht_introspection.verify.novelty import EnvelopeModel, NeighbourModel, TimingModel

SIGNALS = ("wrench", "timing", "wrench_global")
SCALE_QUANTILE = 0.75
"""Each (signal, sub-task) is first scaled by this quantile of its held-out maxima."""
SIGNAL_FLOOR = {"wrench": 0.1, "wrench_global": 0.1, "timing": 0.5}
"""Smallest scale of a signal's maxima (a sub-task whose held-out maxima are all about 0 - a
duration always inside the nominal range - would otherwise turn any excursion into an alarm
threshold of millions)."""
SCORE_CAP = 1e6
"""Scores are capped here, so an unknown sub-task (infinite novelty) still compares and sorts."""


@dataclass
class SignalModels:
    """The fitted models behind the signals (a detector fits the ones it uses)."""

    envelope: EnvelopeModel | None = None
    """The characteriser's view (fitted with the `wrench` signal)."""
    neighbours: NeighbourModel | None = None
    timing: TimingModel | None = None
    global_envelope: EnvelopeModel | None = None
    """The raw-wrench baseline's characteriser view."""
    global_neighbours: NeighbourModel | None = None

    @classmethod
    def fit(
        cls, trials: Sequence[TrialFeatures], config: VerifyConfig, signals: Sequence[str]
    ) -> SignalModels:
        wrench, whole = "wrench" in signals, "wrench_global" in signals
        return cls(
            envelope=EnvelopeModel.fit(trials, config) if wrench else None,
            neighbours=NeighbourModel.fit(trials, config) if wrench else None,
            timing=TimingModel.fit(trials, config) if "timing" in signals else None,
            global_envelope=EnvelopeModel.fit(trials, config, phase_free=True) if whole else None,
            global_neighbours=NeighbourModel.fit(trials, config, phase_free=True)
            if whole
            else None,
        )

    def scores(self, tf: TrialFeatures, signals: Sequence[str]) -> np.ndarray:
        """(ticks, signals) raw scores."""
        cols = []
        for s in signals:
            if s == "wrench" and self.neighbours is not None:
                cols.append(self.neighbours.scores(tf))
            elif s == "timing" and self.timing is not None:
                cols.append(self.timing.scores(tf))
            elif s == "wrench_global" and self.global_neighbours is not None:
                cols.append(self.global_neighbours.scores(tf))
            else:
                raise ValueError(f"signal {s!r} is not fitted")
        if not cols:
            return np.zeros((len(tf.times), 0))
        return np.minimum(np.column_stack(cols), SCORE_CAP)  # inf (unknown sub-task) -> the cap


def conformal_threshold(run_maxima: Sequence[float] | np.ndarray, level: float) -> float:
    """The ceil((n + 1) * level)-th smallest run maximum (the largest when n is too small)."""
    values = np.sort(np.asarray(run_maxima, dtype=float))
    if len(values) == 0:
        return math.inf
    k = math.ceil((len(values) + 1) * level)
    return float(values[min(k, len(values)) - 1])


@dataclass(frozen=True)
class Detection:
    """One run through the detector: normalised scores per tick, the alarm and its onset estimate."""

    times: np.ndarray
    normalised: np.ndarray
    """(ticks, signals) score / threshold; an alarm where any is > 1."""
    alarm: float | None
    """Stream time of the first alarm tick (None: no alarm)."""
    alarm_signal: str = ""
    onset: float | None = None
    """Estimated onset: the last tick before the alarm whose normalised score was below
    onset_fraction (the start of the excursion that raised it)."""
    signals: tuple[str, ...] = ()
    """The signal of each column of `normalised`."""

    @property
    def score(self) -> np.ndarray:
        """Combined score per tick: the largest normalised signal."""
        if self.normalised.shape[1] == 0:
            return np.zeros(len(self.times))
        return np.nan_to_num(self.normalised.max(axis=1), posinf=1e6)


def _held_out_scores(
    successes: Sequence[TrialFeatures],
    config: VerifyConfig,
    signals: tuple[str, ...],
    phases: tuple[str, ...],
    seed: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Cross-fitted calibration: each success scored by models fitted without it. Returns the
    scale of each (signal, sub-task, segment) - the upper quartile of its held-out maxima - and
    each success's maxima in those units (successes, signals, sub-tasks, segments). Needs at
    least 2 successes (Detector.fit checks)."""
    n = len(successes)
    folds = min(config.calibration_folds, n)
    edges = np.asarray(config.threshold_segments_s, dtype=float)
    n_seg = len(edges) + 1
    order = np.random.default_rng(seed).permutation(n)
    maxima = np.zeros((n, len(signals), len(phases), n_seg))
    for k in range(folds):
        held = set(order[k::folds].tolist())
        models = SignalModels.fit([successes[i] for i in order if i not in held], config, signals)
        for i in held:
            tf = successes[i]
            s = models.scores(tf, signals)
            seg = np.searchsorted(edges, tf.elapsed, side="right")
            for j, name in enumerate(tf.phases):
                if name not in phases:
                    continue
                p = phases.index(name)
                for g in range(n_seg):
                    sel = (tf.phase_index == j) & (seg == g)
                    if np.any(sel):
                        maxima[i, :, p, g] = np.maximum(maxima[i, :, p, g], s[sel].max(axis=0))
    floor = np.array([SIGNAL_FLOOR[s] for s in signals])[:, None, None]
    scale = np.maximum(np.quantile(maxima, SCALE_QUANTILE, axis=0), floor)
    return scale, maxima / scale[None]


def _unlike_the_others(ratios: np.ndarray, signals: tuple[str, ...], fence_iqr: float) -> list[int]:
    """Indices of successes whose largest wrench ratio lies beyond the far-out fence of all
    successes' on a log scale, Q3 + fence_iqr * IQR (Tukey's far-out fence at 3); none when
    fence_iqr is 0. Timing is left out of the test: some success always has the shortest or
    longest sub-task, and an otherwise nominal duration scores 0, so its spread says nothing."""
    wrench = [i for i, s in enumerate(signals) if s != "timing"]
    if fence_iqr <= 0 or not wrench or len(ratios) < 4:
        return []
    largest = ratios[:, wrench].reshape(len(ratios), -1).max(axis=1)
    logs = np.log(np.maximum(largest, 1e-12))
    q1, q3 = np.quantile(logs, [0.25, 0.75])
    return [int(i) for i in np.nonzero(logs > q3 + fence_iqr * (q3 - q1))[0]]


@dataclass
class Detector:
    """Signals fitted on successes, with thresholds calibrated on held-out successes."""

    signals: tuple[str, ...]
    models: SignalModels
    thresholds: np.ndarray
    """(signals, phases, segments): each signal's threshold per sub-task and span of time into
    it (config.threshold_segments_s)."""
    config: VerifyConfig
    phases: tuple[str, ...] = ()
    calibration: dict[str, object] = field(default_factory=dict)
    left_out: tuple[str, ...] = ()
    """Successes left out of the models and the calibration (unlike the others)."""

    @classmethod
    def fit(
        cls,
        successes: Sequence[TrialFeatures],
        config: VerifyConfig,
        signals: Sequence[str] = ("wrench", "timing"),
        seed: int = 0,
    ) -> Detector:
        signals = tuple(signals)
        successes = list(successes)
        if min(config.calibration_folds, len(successes)) < 2:
            raise ValueError(
                f"need at least 2 successful trials to calibrate, got {len(successes)}"
            )
        phases = tuple(dict.fromkeys(p for tf in successes for p in tf.phases))
        if not phases:
            raise ValueError("the successful trials have no sub-task events to calibrate on")
        scale, ratios = _held_out_scores(successes, config, signals, phases, seed)
        left_out = _unlike_the_others(ratios, signals, config.nominal_fence_iqr)
        if left_out and len(successes) - len(left_out) >= 2:
            # fitted and calibrated again without them: a success unlike all others (a slip
            # that still snapped in) would widen the nominal model and lift every threshold
            dropped = set(left_out)
            keep = [i for i in range(len(successes)) if i not in dropped]
            scale, ratios = _held_out_scores(
                [successes[i] for i in keep], config, signals, phases, seed
            )
            left_names = [successes[i].trial for i in left_out]
            successes = [successes[i] for i in keep]
        else:
            left_names = []
        n = len(successes)
        combined = ratios.reshape(n, -1).max(axis=1)  # each run's largest ratio
        thresholds = scale * conformal_threshold(combined, 1.0 - config.false_alarm_rate)
        return cls(
            signals,
            SignalModels.fit(successes, config, signals),
            thresholds,
            config,
            phases,
            {
                "successes": n,
                "folds": min(config.calibration_folds, n),
                "level": 1.0 - config.false_alarm_rate,
            },
            tuple(left_names),
        )

    def threshold_of(self, phase: str, elapsed: float) -> np.ndarray:
        """Each signal's threshold at `elapsed` s into sub-task `phase` (the largest of any
        sub-task for one no success had)."""
        seg = int(np.searchsorted(self.config.threshold_segments_s, elapsed, side="right"))
        if phase in self.phases:
            return self.thresholds[:, self.phases.index(phase), seg]
        return (
            self.thresholds.max(axis=(1, 2)) if self.thresholds.size else np.ones(len(self.signals))
        )

    def run(self, tf: TrialFeatures) -> Detection:
        """Score every tick of a trial and find its first alarm."""
        raw = self.models.scores(tf, self.signals)
        thr = np.array(
            [
                self.threshold_of(tf.phases[i] if i >= 0 else "", float(e))
                for i, e in zip(tf.phase_index.astype(int), tf.elapsed, strict=True)
            ]
        ).reshape(len(tf.times), len(self.signals))
        return detection_of(tf.times, raw / thr, self.signals, self.config.onset_fraction)


def detection_of(
    times: np.ndarray, normalised: np.ndarray, signals: Sequence[str], onset_fraction: float
) -> Detection:
    """The alarm (first tick with a normalised score > 1) and its onset estimate."""
    combined = np.nan_to_num(normalised.max(axis=1), posinf=1e6) if normalised.size else None
    if combined is None or not np.any(combined > 1.0):
        return Detection(times, normalised, None, signals=tuple(signals))
    a = int(np.argmax(combined > 1.0))
    below = np.nonzero(combined[:a] < onset_fraction)[0]
    onset = float(times[below[-1] + 1]) if len(below) else float(times[0])
    signal = signals[int(np.nanargmax(np.nan_to_num(normalised[a], posinf=1e6)))]
    return Detection(times, normalised, float(times[a]), signal, onset, tuple(signals))

"""Failure detection: per-tick signals, thresholds calibrated on held-out successes, one alarm.

Signals (each a score per tick, higher = less nominal):
* `wrench`: the sub-task envelope's novelty (novelty.EnvelopeModel, per sub-task and elapsed time);
* `timing`: a sub-task running longer, or ending sooner or later, than any nominal one;
* `wrench_global`: one envelope for the whole trial (the raw-wrench baseline, no state machine).
Each signal's threshold is the conformal quantile of its run maximum over successes held out by
cross-fitting, at level 1 - false_alarm_rate / (number of signals) (Bonferroni), so that the
combined alarm - the first tick at which any signal exceeds its threshold - fires on at most
`false_alarm_rate` of nominal runs. With too few successes for that quantile the threshold is
the largest held-out run maximum.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from rcbht_introspection.verify.config import VerifyConfig
from rcbht_introspection.verify.features import TrialFeatures
from rcbht_introspection.verify.novelty import EnvelopeModel, TimingModel

SIGNALS = ("wrench", "timing", "wrench_global")


@dataclass
class SignalModels:
    """The fitted models behind the signals (a detector fits the ones it uses)."""

    envelope: EnvelopeModel | None = None
    timing: TimingModel | None = None
    global_envelope: EnvelopeModel | None = None

    @classmethod
    def fit(
        cls, trials: Sequence[TrialFeatures], config: VerifyConfig, signals: Sequence[str]
    ) -> SignalModels:
        return cls(
            envelope=EnvelopeModel.fit(trials, config) if "wrench" in signals else None,
            timing=TimingModel.fit(trials, config) if "timing" in signals else None,
            global_envelope=(
                EnvelopeModel.fit(trials, config, phase_free=True)
                if "wrench_global" in signals
                else None
            ),
        )

    def scores(self, tf: TrialFeatures, signals: Sequence[str]) -> np.ndarray:
        """(ticks, signals) raw scores."""
        cols = []
        for s in signals:
            if s == "wrench" and self.envelope is not None:
                cols.append(self.envelope.score_z(self.envelope.z(tf)))
            elif s == "timing" and self.timing is not None:
                cols.append(self.timing.scores(tf))
            elif s == "wrench_global" and self.global_envelope is not None:
                g = self.global_envelope
                cols.append(g.score_z(g.z(tf)))
            else:
                raise ValueError(f"signal {s!r} is not fitted")
        return np.column_stack(cols) if cols else np.zeros((len(tf.times), 0))


def conformal_threshold(run_maxima: Sequence[float], level: float) -> float:
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

    @property
    def score(self) -> np.ndarray:
        """Combined score per tick: the largest normalised signal."""
        if self.normalised.shape[1] == 0:
            return np.zeros(len(self.times))
        return np.nan_to_num(self.normalised.max(axis=1), posinf=1e6)


@dataclass
class Detector:
    """Signals fitted on successes, with thresholds calibrated on held-out successes."""

    signals: tuple[str, ...]
    models: SignalModels
    thresholds: np.ndarray
    config: VerifyConfig
    calibration: dict[str, object] = field(default_factory=dict)

    @classmethod
    def fit(
        cls,
        successes: Sequence[TrialFeatures],
        config: VerifyConfig,
        signals: Sequence[str] = ("wrench", "timing"),
        seed: int = 0,
    ) -> Detector:
        signals = tuple(signals)
        n = len(successes)
        folds = min(config.calibration_folds, n)
        if folds < 2:
            raise ValueError(f"need at least 2 successful trials to calibrate, got {n}")
        order = np.random.default_rng(seed).permutation(n)
        maxima = np.zeros((n, len(signals)))
        for k in range(folds):
            held = order[k::folds]
            rest = [successes[i] for i in order if i not in set(held)]
            models = SignalModels.fit(rest, config, signals)
            for i in held:
                s = models.scores(successes[i], signals)
                maxima[i] = np.nan_to_num(s.max(axis=0), posinf=1e6) if len(s) else 0.0
        level = 1.0 - config.false_alarm_rate / max(len(signals), 1)
        thresholds = np.array(
            [max(conformal_threshold(maxima[:, j], level), 1e-9) for j in range(len(signals))]
        )
        return cls(
            signals,
            SignalModels.fit(successes, config, signals),
            thresholds,
            config,
            {"successes": n, "folds": folds, "level": level, "run_maxima": maxima.tolist()},
        )

    def run(self, tf: TrialFeatures) -> Detection:
        """Score every tick of a trial and find its first alarm."""
        normalised = self.models.scores(tf, self.signals) / self.thresholds[None, :]
        return detection_of(tf.times, normalised, self.signals, self.config.onset_fraction)


def detection_of(
    times: np.ndarray, normalised: np.ndarray, signals: Sequence[str], onset_fraction: float
) -> Detection:
    """The alarm (first tick with a normalised score > 1) and its onset estimate."""
    combined = np.nan_to_num(normalised.max(axis=1), posinf=1e6) if normalised.size else None
    if combined is None or not np.any(combined > 1.0):
        return Detection(times, normalised, None)
    a = int(np.argmax(combined > 1.0))
    below = np.nonzero(combined[:a] < onset_fraction)[0]
    onset = float(times[below[-1] + 1]) if len(below) else float(times[0])
    signal = signals[int(np.nanargmax(np.nan_to_num(normalised[a], posinf=1e6)))]
    return Detection(times, normalised, float(times[a]), signal, onset)

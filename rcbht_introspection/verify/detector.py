"""Failure detection: per-tick signals, thresholds calibrated on held-out successes, one alarm.

Signals (each a score per tick, higher = less nominal):
* `wrench`: distance of the wrench's recent change to the nearest successful trial at the same
  sub-task and time into it (novelty.NeighbourModel on the `change` features);
* `transient`: the same distance on the `jump` features, the departure of single samples from
  the step before: a push that comes and goes (a collision) within the 0.2 s means;
* `departure`: the same distance on the mean wrench's departure from its own level `lag_s` into
  the sub-task (features.SubtaskDeparture): a slip that keeps growing for seconds;
* `timing`: a sub-task running longer, or ending sooner or later, than any nominal one;
* `wrench_global`: the distance of the raw mean wrench by time into the trial (the raw-wrench
  baseline: no state machine, no bias cancelling);
* `hmm`: the successor framework's HMM log-likelihood per sub-task (peers/hmm.py, an anchor
  baseline of `rcbht verify-eval`; imported only when asked for).
Each signal has a threshold per sub-task. Calibration scores successes held out by
cross-fitting (folds grouped by session where the labels name one, so a threshold is tested
on sessions it has not seen): each (signal, sub-task) maximum is divided by the upper quartile
of its held-out maxima, and the run's largest such ratio is its combined score; the thresholds
are those quartiles times the conformal (1 - false_alarm_rate) quantile of the combined scores,
so the alarm fires on about `false_alarm_rate` of nominal runs. A success whose combined score
is above that quantile is no reference (the others do not explain it), and the calibration runs
again without it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rcbht_introspection.verify.config import VerifyConfig
from rcbht_introspection.verify.features import (
    PER_ARM,
    TrialFeatures,
    departure_features,
    kind_columns,
    lag_ticks,
)
from rcbht_introspection.verify.novelty import NeighbourModel, NominalLevel, TimingModel

SCALE_QUANTILE = 0.75
"""Each (signal, sub-task) is first scaled by this quantile of its held-out maxima."""
SIGNAL_FLOOR = {
    "wrench": 0.1,
    "transient": 0.1,
    "wrench_global": 0.1,
    "timing": 0.5,
    "hmm": 0.1,
    "departure": 0.1,
}
"""Smallest scale of a signal's maxima (a sub-task whose held-out maxima are all about 0 would
otherwise turn any excursion into an alarm)."""
SCORE_CAP = 1e6
"""Scores are capped here, so an unknown sub-task (infinite novelty) still compares and sorts."""


@dataclass
class SignalModels:
    """The fitted models behind the signals (a detector fits the ones it uses)."""

    neighbours: NeighbourModel | None = None
    transient: NeighbourModel | None = None
    """The successes' jumps per sub-task (the `transient` signal)."""
    level: NominalLevel | None = None
    """The successes' mean wrench along each sub-task (fitted with the `wrench` signal)."""
    timing: TimingModel | None = None
    global_neighbours: NeighbourModel | None = None
    hmm: HMMSignal | None = None
    departure: NeighbourModel | None = None
    """The successes' departures per sub-task (the `departure` signal)."""
    lag: int = 1
    """The departure's reference: this many ticks into the sub-task (lag_s)."""

    @classmethod
    def fit(
        cls, trials: Sequence[TrialFeatures], config: VerifyConfig, signals: Sequence[str]
    ) -> SignalModels:
        wrench = "wrench" in signals
        return cls(
            neighbours=NeighbourModel.fit(trials, config) if wrench else None,
            transient=NeighbourModel.fit(trials, config, kind="jump", largest=True)
            if "transient" in signals
            else None,
            level=NominalLevel.fit(trials) if wrench else None,
            timing=TimingModel.fit(trials, config) if "timing" in signals else None,
            global_neighbours=NeighbourModel.fit(trials, config, phase_free=True, kind="mean")
            if "wrench_global" in signals
            else None,
            hmm=HMMSignal.fit(trials) if "hmm" in signals else None,
            departure=_departure_model(trials, config) if "departure" in signals else None,
            lag=lag_ticks(config),
        )

    def neighbours_for(self, signal: str) -> NeighbourModel | None:
        """The neighbour model behind `signal` (None: not a neighbour signal, or not fitted)."""
        if signal == "wrench":
            return self.neighbours
        return self.transient if signal == "transient" else None

    def scores(self, tf: TrialFeatures, signals: Sequence[str]) -> np.ndarray:
        """(ticks, signals) raw scores."""
        cols = []
        for s in signals:
            if (neighbours := self.neighbours_for(s)) is not None:
                cols.append(neighbours.scores(tf))
            elif s == "timing" and self.timing is not None:
                cols.append(self.timing.scores(tf))
            elif s == "wrench_global" and self.global_neighbours is not None:
                cols.append(self.global_neighbours.scores(tf))
            elif s == "departure" and self.departure is not None:
                cols.append(self.departure.scores(departure_features(tf, self.lag)))
            elif s == "hmm" and self.hmm is not None:
                cols.append(self.hmm.scores(tf))
            else:
                raise ValueError(f"signal {s!r} is not fitted")
        if not cols:
            return np.zeros((len(tf.times), 0))
        # inf (unknown sub-task) -> the cap
        capped: np.ndarray = np.minimum(np.column_stack(cols), SCORE_CAP)
        return capped


def _departure_model(trials: Sequence[TrialFeatures], config: VerifyConfig) -> NeighbourModel:
    """The successes' departures (their mean blocks) by time into each sub-task."""
    lag = lag_ticks(config)
    return NeighbourModel.fit([departure_features(t, lag) for t in trials], config, kind="mean")


@dataclass
class HMMSignal:
    """The successor framework's detector on the ticks' mean wrench, sub-task by sub-task."""

    detector: Any

    @classmethod
    def fit(cls, trials: Sequence[TrialFeatures]) -> HMMSignal:
        from rcbht_introspection.peers.hmm import HMMDetector

        sequences: dict[str, list[np.ndarray]] = {}
        for trial in trials:
            for name, sel in _parts(trial):
                sequences.setdefault(name, []).append(trial.features[sel][:, _means(trial)])
        return cls(HMMDetector().fit(sequences))

    def scores(self, tf: TrialFeatures) -> np.ndarray:
        """The score of every tick (0 before the first sub-task); each sub-task scored once."""
        out = np.zeros(len(tf.times))
        for name, sel in _parts(tf):
            out[sel] = np.nan_to_num(
                self.detector.score(name, tf.features[sel][:, _means(tf)]), nan=SCORE_CAP
            )
        return out


def _parts(tf: TrialFeatures) -> list[tuple[str, np.ndarray]]:
    """(sub-task, its ticks' mask) of every sub-task with ticks."""
    masks = [(n, tf.phase_index == j) for j, n in enumerate(tf.phases)]
    return [(n, m) for n, m in masks if np.any(m)]


def _means(tf: TrialFeatures) -> np.ndarray:
    return kind_columns("mean", tf.features.shape[1] // PER_ARM)


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
    """Estimated onset: the first tick of the excursion that raised the alarm (after the last
    tick whose normalised score was below onset_fraction)."""
    signals: tuple[str, ...] = ()
    """The signal of each column of `normalised`."""

    @property
    def score(self) -> np.ndarray:
        """Combined score per tick: the largest normalised signal."""
        if self.normalised.shape[1] == 0:
            return np.zeros(len(self.times))
        combined: np.ndarray = np.nan_to_num(self.normalised.max(axis=1), posinf=SCORE_CAP)
        return combined


def calibration_folds(
    names: Sequence[str], groups: Mapping[str, str] | None, folds: int, seed: int
) -> list[list[int]]:
    """Indices of the held-out successes of each fold: whole sessions (`groups`: trial ->
    session) dealt round-robin in a seeded order, or single trials when no session is named."""
    keys = [groups.get(n, n) if groups else n for n in names]
    sessions = sorted(set(keys))
    order = np.random.default_rng(seed).permutation(len(sessions))
    k = min(folds, len(sessions))
    fold_of = {sessions[j]: i % k for i, j in enumerate(order)}
    return [[i for i, key in enumerate(keys) if fold_of[key] == f] for f in range(k)]


def _held_out_scores(
    successes: Sequence[TrialFeatures],
    config: VerifyConfig,
    signals: tuple[str, ...],
    phases: tuple[str, ...],
    held: list[list[int]],
    references: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Cross-fitted calibration: each success scored by models fitted on the `references`
    (mask) outside its fold. Returns the scale of each (signal, sub-task) - the upper quartile
    of its held-out maxima - and each success's maxima in those units (successes, signals,
    sub-tasks)."""
    maxima = np.zeros((len(successes), len(signals), len(phases)))
    for fold in held:
        out = set(fold)
        models = SignalModels.fit(
            [tf for i, tf in enumerate(successes) if i not in out and references[i]],
            config,
            signals,
        )
        for i in fold:
            tf = successes[i]
            s = models.scores(tf, signals)
            for j, name in enumerate(tf.phases):
                sel = tf.phase_index == j
                if name in phases and np.any(sel):
                    p = phases.index(name)
                    maxima[i, :, p] = np.maximum(maxima[i, :, p], s[sel].max(axis=0))
    floor = np.array([SIGNAL_FLOOR[s] for s in signals])[:, None]
    scale = np.maximum(np.quantile(maxima, SCALE_QUANTILE, axis=0), floor)
    return scale, maxima / scale[None]


def _calibrate(
    successes: Sequence[TrialFeatures],
    config: VerifyConfig,
    signals: tuple[str, ...],
    phases: tuple[str, ...],
    held: list[list[int]],
) -> tuple[np.ndarray, np.ndarray]:
    """The thresholds (signals, sub-tasks) and the successes kept as references. A success whose
    held-out combined score is above the conformal factor, one the others do not explain (a
    near-failure that still succeeded), would make what resembles it look nominal: it is scored
    but no reference, unless the calibration without it leaves another success unexplained
    (then it is one of a kind that recurs, and all stay references)."""
    level = 1.0 - config.false_alarm_rate
    everyone = np.ones(len(successes), dtype=bool)
    scale, ratios = _held_out_scores(successes, config, signals, phases, held, everyone)
    combined = ratios.reshape(len(successes), -1).max(axis=1)  # each run's largest ratio
    factor = conformal_threshold(combined, level)
    references = combined <= factor
    if references.all():
        return scale * factor, everyone
    scale2, ratios2 = _held_out_scores(successes, config, signals, phases, held, references)
    combined2 = ratios2.reshape(len(successes), -1).max(axis=1)
    if np.any(combined2[references] > factor):
        return scale * factor, everyone
    return scale2 * conformal_threshold(combined2, level), references


@dataclass
class Detector:
    """Signals fitted on successes, with thresholds calibrated on held-out successes."""

    signals: tuple[str, ...]
    models: SignalModels
    thresholds: np.ndarray
    """(signals, phases): each signal's threshold per sub-task."""
    config: VerifyConfig
    phases: tuple[str, ...] = ()
    calibration: dict[str, object] = field(default_factory=dict)

    @classmethod
    def fit(
        cls,
        successes: Sequence[TrialFeatures],
        config: VerifyConfig,
        signals: Sequence[str] | None = None,
        seed: int = 0,
        groups: Mapping[str, str] | None = None,
    ) -> Detector:
        """`signals`: None for the config's; `groups`: trial -> session, for folds that hold out
        whole sessions."""
        signals = tuple(config.signals if signals is None else signals)
        successes = list(successes)
        held = calibration_folds(
            [tf.trial for tf in successes], groups, config.calibration_folds, seed
        )
        if len(held) < 2:
            raise ValueError(
                f"need at least 2 successful trials (or sessions) to calibrate, got {len(held)}"
            )
        phases = tuple(dict.fromkeys(p for tf in successes for p in tf.phases))
        if not phases:
            raise ValueError("the successful trials have no sub-task events to calibrate on")
        thresholds, references = _calibrate(successes, config, signals, phases, held)
        calibration: dict[str, object] = {
            "successes": len(successes),
            "folds": len(held),
            "grouped_by_session": bool(groups),
            "level": 1.0 - config.false_alarm_rate,
            "unexplained": [tf.trial for tf, r in zip(successes, references, strict=True) if not r],
        }
        kept = [tf for tf, r in zip(successes, references, strict=True) if r]
        models = SignalModels.fit(kept, config, signals)
        return cls(signals, models, thresholds, config, phases, calibration)

    def threshold_of(self, phase: str) -> np.ndarray:
        """Each signal's threshold in sub-task `phase` (the largest of any sub-task for one no
        success had)."""
        if phase in self.phases:
            return self.thresholds[:, self.phases.index(phase)]
        return self.thresholds.max(axis=1) if self.thresholds.size else np.ones(len(self.signals))

    def run(self, tf: TrialFeatures) -> Detection:
        """Score every tick of a trial and find its first alarm."""
        raw = self.models.scores(tf, self.signals)
        thr = np.array(
            [self.threshold_of(tf.phases[i] if i >= 0 else "") for i in tf.phase_index.astype(int)]
        ).reshape(len(tf.times), len(self.signals))
        return detection_of(tf.times, raw / thr, self.signals, self.config.onset_fraction)


def detection_of(
    times: np.ndarray, normalised: np.ndarray, signals: Sequence[str], onset_fraction: float
) -> Detection:
    """The alarm (first tick with a normalised score > 1) and its onset estimate."""
    combined = np.nan_to_num(normalised.max(axis=1), posinf=SCORE_CAP) if normalised.size else None
    if combined is None or not np.any(combined > 1.0):
        return Detection(times, normalised, None, signals=tuple(signals))
    a = int(np.argmax(combined > 1.0))
    below = np.nonzero(combined[:a] < onset_fraction)[0]
    onset = float(times[below[-1] + 1]) if len(below) else float(times[0])
    signal = signals[int(np.nanargmax(np.nan_to_num(normalised[a], posinf=SCORE_CAP)))]
    return Detection(times, normalised, float(times[a]), signal, onset, tuple(signals))

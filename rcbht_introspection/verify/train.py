"""Train a verifier from labelled trials: the detector on the successes, the characteriser on
the failures (from their labelled onset, else the start of their first failing sub-task)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from rcbht_introspection.io.trial import Trial
from rcbht_introspection.verify.characterise import Characteriser, label_matrix
from rcbht_introspection.verify.config import VerifyConfig
from rcbht_introspection.verify.detector import Detector
from rcbht_introspection.verify.evidence import EvidenceReader, arms_of, namings, reader_of
from rcbht_introspection.verify.features import TrialFeatures, trial_features
from rcbht_introspection.verify.labels import DIRECTION_AXES, TrialLabel
from rcbht_introspection.verify.model_file import VerifierModel
from rcbht_introspection.verify.novelty import TimingModel


def fallback_onset(tf: TrialFeatures, timing: TimingModel) -> float:
    """Start of the first failing sub-task: the first whose duration lies outside the nominal
    range (the last running one when none does)."""
    if not tf.phases:
        return 0.0  # no sub-task events: from the start
    ends = [*tf.starts[1:], tf.end]
    for name, s, e in zip(tf.phases, tf.starts, ends, strict=True):
        if timing.ended(name, float(e - s)) > 0:
            return float(s)
    return float(tf.starts[-1]) if len(tf.starts) else 0.0


def onset_for(label: TrialLabel, tf: TrialFeatures, timing: TimingModel) -> tuple[float, str]:
    """(onset, where it came from) of a failed trial."""
    if label.onset is not None:
        return label.onset, "label"
    return fallback_onset(tf, timing), "first failing sub-task"


@dataclass(frozen=True)
class Fitted:
    """One method's fitted parts: the detector, the evidence view and the characteriser."""

    detector: Detector
    reader: EvidenceReader
    characteriser: Characteriser | None


def fit_method(
    successes: Sequence[TrialFeatures],
    failures: Sequence[tuple[TrialFeatures, TrialLabel, float]],
    config: VerifyConfig,
    signals: Sequence[str],
    view: str,
    seed: int = 0,
    groups: Mapping[str, str] | None = None,
) -> Fitted:
    """Detector on the successes; characteriser on the failures' evidence, one row at every
    tick at which the class is named again: from the labelled onset, and from the detector's
    own alarm and onset estimate where it raises one (the evidence as the live verifier will
    read it, which starts later or sooner than the label; its reference `lag_s` before). The
    verifier's view (`wrench`) adds the shape head; the baselines' views do not."""
    detector = Detector.fit(successes, config, signals, seed=seed, groups=groups)
    if view == "timing" and detector.models.timing is None:
        detector.models.timing = TimingModel.fit(successes, config)
    reader = reader_of(detector, view, arms_of(successes[0]))
    rows: list[np.ndarray] = []
    windows: list[np.ndarray] = []
    labels: list[TrialLabel] = []
    for tf, label, onset in failures:
        ticks = reader.ticks(tf)
        starts = [(onset, onset, 0.0)]
        d = detector.run(tf)
        if d.alarm is not None and d.onset is not None:
            starts.append((d.onset, d.alarm, config.lag_s))
        for begin, start, lead in starts:
            for reading in namings(reader, config.evidence_s, begin, ticks, start, lead):
                rows.append(reading.features)
                windows.append(reading.window)
                labels.append(label)
    shape = windows if view == "wrench" else []
    char = None
    if rows:
        y = label_matrix(labels)
        trials = [lb.trial for lb in labels]
        char = Characteriser(random_state=seed).fit(np.vstack(rows), y, shape or None, trials)
    return Fitted(detector, reader, char)


def train_verifier(
    trials: Sequence[Trial],
    labels: Mapping[str, TrialLabel],
    config: VerifyConfig,
    seed: int = 0,
) -> VerifierModel:
    """A verifier for the arms of `trials` (all must have the same arms)."""
    arms = {t.arms for t in trials}
    if len(arms) != 1:
        raise ValueError(f"trials mix arm sets {sorted(arms)}")
    feats = {t.name: trial_features(t, config) for t in trials}
    successes = [feats[t.name] for t in trials if not labels[t.name].failed]
    failed = [t.name for t in trials if labels[t.name].failed]
    timing = TimingModel.fit(successes, config)  # all successes, as verify-eval's onsets
    failures = [(feats[n], labels[n], onset_for(labels[n], feats[n], timing)[0]) for n in failed]
    groups = {n: lb.session for n, lb in labels.items() if lb.session}
    fitted = fit_method(successes, failures, config, config.signals, "wrench", seed, groups)
    return VerifierModel(
        arms=arms.pop(),
        detector=fitted.detector,
        characteriser=fitted.characteriser,
        trained_on={
            "successes": len(successes),
            "sessions": len(set(groups.values())),
            "failures": len(failed),
            "classes": sorted({labels[n].failure_class for n in failed}),
            "deviation_by_class": deviations_by_class([labels[n] for n in failed]),
        },
    )


def deviations_by_class(failed: Sequence[TrialLabel]) -> dict[str, dict[str, dict[str, float]]]:
    """Per failure class with labelled deviations: `size`, the median per axis (a planner's
    first step), and `spread`, half the 10-90 % range (its next step when that missed)."""
    out: dict[str, dict[str, dict[str, float]]] = {}
    for cls in sorted({lb.failure_class for lb in failed}):
        mine = [lb for lb in failed if lb.failure_class == cls]
        size, spread = {}, {}
        for i, axis in enumerate(DIRECTION_AXES):
            sizes = [abs(lb.deviation[i]) for lb in mine if lb.deviation and lb.deviation[i]]
            if sizes:
                low, mid, high = np.percentile(sizes, [10, 50, 90])
                size[axis] = round(float(mid), 7)
                spread[axis] = round(float(high - low) / 2, 7)
        if size:
            out[cls] = {"size": size, "spread": spread}
    return out

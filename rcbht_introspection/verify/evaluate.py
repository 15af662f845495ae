"""`rcbht verify-eval`'s protocol: detection and characterisation scored per trial, grouped folds.

The anchors' rules: a failure run's alarm is a true positive only within `gate_s` after the
labelled onset (an alarm before onset is a false alarm), any alarm on a nominal run is a false
positive, a run raises at most one alarm (it latches). The verifier is scored beside two
baselines that need no grammar and no sub-task envelope: `raw_wrench` (one envelope of the raw
wrench features for the whole trial) and `timing` (sub-task durations only).
"""

from __future__ import annotations

import warnings
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from sklearn.metrics import roc_auc_score
from sklearn.model_selection import StratifiedKFold

from rcbht_introspection.io.trial import Trial
from rcbht_introspection.verify.characterise import Characteriser, EvidenceView, wrench_means
from rcbht_introspection.verify.config import VerifyConfig
from rcbht_introspection.verify.detector import Detector
from rcbht_introspection.verify.features import TrialFeatures, trial_features
from rcbht_introspection.verify.labels import DIRECTION_AXES, TrialLabel
from rcbht_introspection.verify.mismatch import Contradiction, with_mismatch
from rcbht_introspection.verify.novelty import TimingModel
from rcbht_introspection.verify.train import onset_for

GATE_S = 1.0
TRAIN_PREFIX = "train:"
"""Key prefix of training trials in a transfer evaluation (names may repeat across sets)."""
METHODS: dict[str, tuple[tuple[str, ...], str]] = {
    "verifier": (("wrench", "timing"), "envelope"),
    "raw_wrench": (("wrench_global",), "global_envelope"),
    "timing": (("timing",), "timing"),
}
"""Method -> (detector signals, evidence view of its characteriser)."""
WITH_MISMATCH = "verifier_mismatch"
"""The verifier with the mismatch signal (verify/mismatch.py): scored when the classifier's
final verdicts of the test trials are given."""
CLASS_EVIDENCE_S = (0.0, 0.5, 1.0)
"""Class accuracy is also reported this long after the alarm."""


@dataclass(frozen=True)
class RunResult:
    """One test trial through one method."""

    trial: str
    label: TrialLabel
    onset: float | None
    """The onset scored against: the label's, or the start of the first failing sub-task."""
    onset_source: str
    run_score: float
    alarm: float | None
    alarm_signal: str
    onset_estimate: float | None
    predicted_class: str
    class_by_evidence: dict[str, str]
    class_given_onset: str
    directions: dict[str, str]
    directions_given_onset: dict[str, str]
    times: np.ndarray
    """Tick times and the combined score (largest signal over its threshold) per tick."""
    score: np.ndarray
    classes_over_time: list[tuple[float, str]]
    """(tick time, class) after the alarm, as the live verifier would publish them."""


def view_of(detector: Detector, view: str) -> EvidenceView:
    """The model a method's characteriser reads evidence through."""
    model = getattr(detector.models, view)
    if model is None:
        raise ValueError(f"the detector has no {view}")
    return model


def _fold_results(
    train: Sequence[str],
    test: Sequence[str],
    feats: Mapping[str, TrialFeatures],
    labels: Mapping[str, TrialLabel],
    config: VerifyConfig,
    seed: int,
    contradictions: Mapping[str, Sequence[Contradiction]] | None = None,
    left_out: list[tuple[str, str]] | None = None,
) -> dict[str, list[RunResult]]:
    successes = [feats[n] for n in train if not labels[n].failed]
    timing = TimingModel.fit(successes, config)

    def onset_of(name: str) -> tuple[float | None, str]:
        if not labels[name].failed:
            return None, ""
        return onset_for(labels[name], feats[name], timing)

    out: dict[str, list[RunResult]] = {}
    methods = dict(METHODS)
    if contradictions is not None:
        methods[WITH_MISMATCH] = METHODS["verifier"]
    failures = [(feats[n], labels[n], onset_of(n)[0]) for n in train if labels[n].failed]
    onsets_known = [(f, lb, float(o)) for f, lb, o in failures if o is not None]
    fitted: dict[tuple[str, ...], Detector] = {}
    characterisers: dict[tuple[tuple[str, ...], str], Characteriser | None] = {}
    for method, (signals, view) in methods.items():
        if signals not in fitted:
            fitted[signals] = Detector.fit(successes, config, signals, seed=seed)
            if left_out is not None:
                left_out.extend((method, name) for name in fitted[signals].left_out)
        detector = fitted[signals]
        ev = view_of(detector, view)
        if (signals, view) not in characterisers:  # the mismatch variant shares the verifier's
            characterisers[signals, view] = (
                Characteriser.fit(onsets_known, ev, config, seed) if failures else None
            )
        char = characterisers[signals, view]
        results = []
        for name in test:
            tf, label = feats[name], labels[name]
            onset, source = onset_of(name)
            d = detector.run(tf)
            if method == WITH_MISMATCH and contradictions is not None:
                d = with_mismatch(d, contradictions.get(name, ()), config)
            predicted, given = "", ""
            dirs: dict[str, str] = {}
            dirs_given: dict[str, str] = {}
            by_evidence: dict[str, str] = {}
            over_time: list[tuple[float, str]] = []
            if char is not None and label.failed:
                z, means = ev.z(tf), wrench_means(tf)
                if d.alarm is not None and d.onset is not None:
                    predicted, _, dirs = char.predict(tf, z, d.onset, tf.end, means)
                    for span in CLASS_EVIDENCE_S:
                        by_evidence[str(span)] = char.predict(
                            tf, z, d.onset, min(d.alarm + span, tf.end), means
                        )[0]
                    ticks = tf.times[tf.times >= d.alarm]
                    for g in ticks[:: max(1, len(ticks) // 40)]:
                        over_time.append(
                            (float(g), char.predict(tf, z, d.onset, float(g), means)[0])
                        )
                if onset is not None:
                    given, _, dirs_given = char.predict(tf, z, onset, tf.end, means)
            results.append(
                RunResult(
                    trial=name,
                    label=label,
                    onset=onset,
                    onset_source=source,
                    run_score=float(np.max(d.score)) if len(d.score) else 0.0,
                    alarm=d.alarm,
                    alarm_signal=d.alarm_signal,
                    onset_estimate=d.onset,
                    predicted_class=predicted,
                    class_by_evidence=by_evidence,
                    class_given_onset=given,
                    directions=dirs,
                    directions_given_onset=dirs_given,
                    times=d.times,
                    score=d.score,
                    classes_over_time=over_time,
                )
            )
        out[method] = results
    return out


def _ratio(a: float, b: float) -> float | None:
    return float(a / b) if b else None


def metrics(results: Sequence[RunResult], gate_s: float = GATE_S) -> dict[str, Any]:
    """The protocol's numbers for one method's test runs."""
    nominal = [r for r in results if not r.label.failed]
    failed = [r for r in results if r.label.failed]
    fp_nominal = sum(r.alarm is not None for r in nominal)
    tp = [
        r
        for r in failed
        if r.alarm is not None and r.onset is not None and r.onset <= r.alarm <= r.onset + gate_s
    ]
    early = sum(r.alarm is not None and r.onset is not None and r.alarm < r.onset for r in failed)
    fp = fp_nominal + early
    precision = _ratio(len(tp), len(tp) + fp)
    recall = _ratio(len(tp), len(failed))
    f1 = (
        2 * precision * recall / (precision + recall)
        if precision is not None and recall is not None and precision + recall > 0
        else 0.0
    )
    delays = [r.alarm - r.onset for r in tp if r.alarm is not None and r.onset is not None]
    out: dict[str, Any] = {
        "runs": len(results),
        "nominal_runs": len(nominal),
        "failure_runs": len(failed),
        "roc_auc": _auc(nominal, failed),
        "roc_auc_per_class": {
            c: _auc(nominal, [r for r in failed if r.label.failure_class == c])
            for c in sorted({r.label.failure_class for r in failed})
        },
        "detection_accuracy": _ratio(len(tp) + len(nominal) - fp_nominal, len(results)),
        "precision": precision,
        "recall": recall,
        "f1": f1,
        "false_alarms_per_nominal_run": _ratio(fp_nominal, len(nominal)),
        "early_alarms": early,
        "late_or_missed": len(failed) - len(tp) - early,
        "detection_delay_s": {
            "p50": float(np.percentile(delays, 50)) if delays else None,
            "p90": float(np.percentile(delays, 90)) if delays else None,
        },
        "class_accuracy": _ratio(
            sum(r.predicted_class == r.label.failure_class for r in failed), len(failed)
        ),
        "class_accuracy_after_alarm_s": {
            s: _ratio(
                sum(r.class_by_evidence.get(s) == r.label.failure_class for r in failed),
                len(failed),
            )
            for s in (str(x) for x in CLASS_EVIDENCE_S)
        },
        "class_accuracy_given_onset": _ratio(
            sum(r.class_given_onset == r.label.failure_class for r in failed), len(failed)
        ),
        "per_class_recall": {
            c: _ratio(
                sum(r.predicted_class == c for r in failed if r.label.failure_class == c),
                sum(r.label.failure_class == c for r in failed),
            )
            for c in sorted({r.label.failure_class for r in failed})
        },
    }
    deviated = [r for r in failed if r.label.directions() is not None]
    if deviated:
        for key, attr in (
            ("direction_accuracy", "directions"),
            ("direction_accuracy_given_onset", "directions_given_onset"),
        ):
            out[key] = {
                a: _ratio(
                    sum(getattr(r, attr).get(a) == r.label.directions()[a] for r in deviated),  # type: ignore[index]
                    len(deviated),
                )
                for a in DIRECTION_AXES
            }
    return out


def _auc(nominal: Sequence[RunResult], failed: Sequence[RunResult]) -> float | None:
    if not nominal or not failed:
        return None
    y = [0] * len(nominal) + [1] * len(failed)
    s = [r.run_score for r in nominal] + [r.run_score for r in failed]
    return float(roc_auc_score(y, s))


def verify_runs(
    trials: Sequence[Trial],
    labels: Mapping[str, TrialLabel],
    config: VerifyConfig,
    folds: int | None = 5,
    seed: int = 0,
    train: Sequence[Trial] = (),
    progress: Callable[[str], None] | None = None,
    train_labels: Mapping[str, TrialLabel] | None = None,
    contradictions: Mapping[str, Sequence[Contradiction]] | None = None,
    left_out: list[tuple[str, str]] | None = None,
) -> dict[str, list[RunResult]]:
    """Every test run of every method: stratified `folds` over `trials` (None: leave one trial
    out), or fitted on `train` and tested on `trials` (transfer; training trials are kept apart
    from the test trials even when their names are the same, as in two simulated sets).
    `contradictions` (test trial -> the classifier's contradicting final verdicts) adds the
    verifier with the mismatch signal (WITH_MISMATCH). `left_out` collects (method, trial) for the
    successes each fold's detectors left out of their nominal model (Detector.fit)."""
    feats = {t.name: trial_features(t, config) for t in trials}
    labels = dict(labels)
    names = [t.name for t in trials]
    splits: list[tuple[list[str], list[str]]]
    if train:
        keys = [TRAIN_PREFIX + t.name for t in train]
        for key, t in zip(keys, train, strict=True):
            feats[key] = trial_features(t, config)
            labels[key] = (train_labels or labels)[t.name]
        splits = [(keys, names)]
    elif folds is None:
        splits = [([m for m in names if m != n], [n]) for n in names]
    else:
        y = [labels[n].failure_class if labels[n].failed else "success" for n in names]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # a class with fewer trials than folds
            kfold = StratifiedKFold(n_splits=folds, shuffle=True, random_state=seed)
            splits = [
                ([names[i] for i in a], [names[i] for i in b]) for a, b in kfold.split(names, y)
            ]
    runs: dict[str, list[RunResult]] = {}
    for k, (tr, te) in enumerate(splits):
        if progress is not None:
            progress(f"fold {k + 1}/{len(splits)}")
        fold = _fold_results(tr, te, feats, labels, config, seed, contradictions, left_out)
        for method, res in fold.items():
            runs.setdefault(method, []).extend(res)
    return runs


def summarise(
    runs: Mapping[str, Sequence[RunResult]],
    config: VerifyConfig,
    protocol: str,
    left_out: Sequence[tuple[str, str]] = (),
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The JSON summary (the verifier's numbers, the baselines beside) and per-run records;
    `left_out`: (method, trial) of each success a fold's detector left out of its nominal
    model, counted per method and trial."""
    main = metrics(runs["verifier"])
    sources = [r.onset_source for r in runs["verifier"] if r.label.failed]
    left: dict[str, dict[str, int]] = {}  # method -> trial -> folds that left it out
    for (method, trial), folds in sorted(Counter(left_out).items()):
        left.setdefault(method, {})[trial] = folds
    summary: dict[str, Any] = {
        **main,
        "protocol": {
            "folds": protocol,
            "gate_s": GATE_S,
            "false_alarm_rate_target": config.false_alarm_rate,
            "onset_source": {s: sources.count(s) for s in sorted(set(sources))},
            "successes_left_out": left,
        },
        "baselines": {m: metrics(runs[m]) for m in METHODS if m != "verifier"},
    }
    if WITH_MISMATCH in runs:
        summary[WITH_MISMATCH] = metrics(runs[WITH_MISMATCH])
    records = [
        {
            "method": m,
            "trial": r.trial,
            "outcome": r.label.outcome,
            "failure_class": r.label.failure_class,
            "onset": r.onset,
            "onset_source": r.onset_source,
            "run_score": r.run_score,
            "alarm": r.alarm,
            "alarm_signal": r.alarm_signal,
            "onset_estimate": r.onset_estimate,
            "predicted_class": r.predicted_class,
            "directions": r.directions,
        }
        for m in runs
        for r in runs[m]
    ]
    return summary, records

"""`rcbht verify-eval`'s protocol: detection and characterisation scored per trial, grouped folds.

The anchors' rules: a failure run's alarm is a true positive only within `gate_s` after the
labelled onset (an alarm before onset is a false alarm), any alarm on a nominal run is a false
positive, a run raises at most one alarm (it latches). The verifier is scored beside two
trivial baselines, `raw_wrench` (the raw mean wrench by time into the trial, no state machine,
no bias cancelling) and `timing` (sub-task durations only), and beside the anchors' methods
(PEERS: the successor framework's HMMs and MiniRocket).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from joblib import Parallel, delayed
from sklearn.metrics import roc_auc_score
from sklearn.model_selection import StratifiedKFold

from rcbht_introspection.io.trial import Trial
from rcbht_introspection.verify.characterise import label_matrix, sign_table
from rcbht_introspection.verify.config import VerifyConfig
from rcbht_introspection.verify.detector import Detection
from rcbht_introspection.verify.evidence import named_at, namings
from rcbht_introspection.verify.features import TrialFeatures, trial_features
from rcbht_introspection.verify.labels import DIRECTION_AXES, TrialLabel
from rcbht_introspection.verify.mismatch import Contradiction, with_mismatch
from rcbht_introspection.verify.novelty import TimingModel
from rcbht_introspection.verify.train import Fitted, fit_method, onset_for

GATE_S = 1.0
TRAIN_PREFIX = "train:"
"""Key prefix of training trials in a transfer evaluation (names may repeat across sets)."""
METHODS: dict[str, tuple[tuple[str, ...], str]] = {
    "verifier": ((), "wrench"),
    "raw_wrench": (("wrench_global",), "raw"),
    "timing": (("timing",), "timing"),
}
"""Method -> (detector signals, evidence view of its characteriser); the verifier's signals
are its config's (`signals`)."""
PEERS = ("hmm", "minirocket")
"""The anchors' methods (peers/): `hmm` detects with the successor framework's HMM per sub-task
and names the class by one HMM per class; `minirocket` names the class by MiniRocket features
and a ridge classifier, on the verifier's alarms (it has no detector of its own)."""
PEER_LEAD_S = 0.1
"""The peers' window starts this long before the onset."""
WITH_MISMATCH = "verifier_mismatch"
"""The verifier with the mismatch signal (verify/mismatch.py): scored when the classifier's
final verdicts of the test trials are given."""
CLASS_EVIDENCE_S = (0.0, 0.5, 1.0)
"""Class accuracy is also reported this long after the alarm."""
Raw = tuple[np.ndarray, np.ndarray]
"""A trial's stream times and wrench samples (all arms side by side)."""


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
    """(tick time, class) at each naming after the alarm, as the live verifier publishes them."""


@dataclass(frozen=True)
class Naming:
    """What a method's characteriser says of one evidence span: its class over time, its last
    class and directions."""

    over_time: list[tuple[float, str]]
    last: str = ""
    directions: dict[str, str] = field(default_factory=dict)


NO_NAMING = Naming([])


def _ours(fitted: Fitted, tf: TrialFeatures, onset: float, start: float, lead: float) -> Naming:
    """The characteriser's namings from `start` (the alarm) on, evidence from `onset` (its
    reference `lead` before: `lag_s` for an onset the detector estimated, as live)."""
    char = fitted.characteriser
    if char is None:
        return NO_NAMING
    ticks = fitted.reader.ticks(tf)
    evidence = namings(fitted.reader, _spans(fitted), onset, ticks, start, lead)
    named = [(r.time, char.characterise(r.features, r.window)) for r in evidence]
    if not named:
        return NO_NAMING
    return Naming([(t, n[0]) for t, n in named], named[-1][1][0], named[-1][1][2])


def _spans(fitted: Fitted) -> tuple[float, ...]:
    return fitted.detector.config.evidence_s


@dataclass
class Fold:
    """One fold's training data, fitted methods and onsets."""

    successes: list[TrialFeatures]
    failures: list[tuple[TrialFeatures, TrialLabel, float]]
    timing: TimingModel
    config: VerifyConfig
    seed: int
    groups: dict[str, str]
    fitted: dict[str, Fitted] = field(default_factory=dict)
    peers: dict[str, Any] = field(default_factory=dict)
    signs: dict[str, dict[str, str]] = field(default_factory=dict)
    """Failure class -> its deviation signs (the training labels' sign table)."""


def _make_fold(
    train: Sequence[str],
    feats: Mapping[str, TrialFeatures],
    labels: Mapping[str, TrialLabel],
    config: VerifyConfig,
    seed: int,
) -> Fold:
    successes = [feats[n] for n in train if not labels[n].failed]
    timing = TimingModel.fit(successes, config)
    failed = [n for n in train if labels[n].failed]
    failures = [(feats[n], labels[n], onset_for(labels[n], feats[n], timing)[0]) for n in failed]
    groups = {n: labels[n].session for n in train if labels[n].session}
    table = sign_table(label_matrix([labels[n] for n in failed]))
    signs = {cls: dict(zip(DIRECTION_AXES, key, strict=True)) for key, cls in table.items()}
    return Fold(successes, failures, timing, config, seed, groups, signs=signs)


def _peer_window(raw: Raw, start: float, until: float) -> np.ndarray:
    """The wrench samples in [start - PEER_LEAD_S, until] (at least the last one before)."""
    t, w = raw
    sel = (t >= start - PEER_LEAD_S - 1e-9) & (t <= until + 1e-9)
    if not np.any(sel):
        sel = np.arange(len(t)) == max(int(np.searchsorted(t, until, "right")) - 1, 0)
    return w[sel]


def _fit_peers(
    fold: Fold, failed: Sequence[str], raws: Mapping[str, Raw], peers: Sequence[str]
) -> None:
    """The anchors' classifiers `peers` on the training failures' windows [onset - lead, end]
    (`failed`: the keys of fold.failures, in its order; a --train trial's key is not its name)."""
    from rcbht_introspection.peers.hmm import HMMClassifier
    from rcbht_introspection.peers.minirocket import MiniRocketClassifier

    if not fold.failures or not peers:
        return
    windows = [
        _peer_window(raws[n], o, tf.end)
        for n, (tf, _, o) in zip(failed, fold.failures, strict=True)
    ]
    y = [lb.failure_class for _, lb, _ in fold.failures]
    if "hmm" in peers:
        fold.peers["hmm"] = HMMClassifier(random_state=fold.seed).fit(windows, y)
    if "minirocket" in peers:
        fold.peers["minirocket"] = MiniRocketClassifier(random_state=fold.seed).fit(windows, y)


def _peer_naming(
    fold: Fold, method: str, raw: Raw, onset: float, start: float, end: float
) -> Naming:
    """The peer's class at the alarm + CLASS_EVIDENCE_S and at the end."""
    model = fold.peers.get(method)
    if model is None:
        return NO_NAMING
    times = sorted({min(start + s, end) for s in CLASS_EVIDENCE_S} | {end})
    named = [str(c) for c in model.predict([_peer_window(raw, onset, t) for t in times])]
    return Naming(list(zip(times, named, strict=True)), named[-1], fold.signs.get(named[-1], {}))


def _detector_of(fold: Fold, method: str) -> Fitted:
    """The method's fitted parts (peers: the hmm detector; minirocket: the verifier's)."""
    key = {"verifier_mismatch": "verifier", "minirocket": "verifier"}.get(method, method)
    if key not in fold.fitted:
        signals, view = METHODS.get(key, (("hmm",), "wrench"))
        signals = signals or fold.config.signals
        failures = fold.failures if key in METHODS else []
        fold.fitted[key] = fit_method(
            fold.successes, failures, fold.config, signals, view, fold.seed, fold.groups
        )
    return fold.fitted[key]


def _run(
    fold: Fold,
    method: str,
    name: str,
    feats: Mapping[str, TrialFeatures],
    labels: Mapping[str, TrialLabel],
    raws: Mapping[str, Raw],
    contradictions: Mapping[str, Sequence[Contradiction]] | None,
) -> RunResult:
    """One test trial through one method."""
    tf, label = feats[name], labels[name]
    fitted = _detector_of(fold, method)
    d: Detection = fitted.detector.run(tf)
    if method == WITH_MISMATCH and contradictions is not None:
        d = with_mismatch(d, contradictions.get(name, ()), fold.config)
    onset, source = onset_for(label, tf, fold.timing) if label.failed else (None, "")
    after, given = NO_NAMING, NO_NAMING
    if label.failed:
        if method in PEERS and method in fold.peers:
            if d.alarm is not None and d.onset is not None:
                after = _peer_naming(fold, method, raws[name], d.onset, d.alarm, tf.end)
            if onset is not None:
                given = _peer_naming(fold, method, raws[name], onset, tf.end, tf.end)
        elif method not in PEERS:
            if d.alarm is not None and d.onset is not None:
                after = _ours(fitted, tf, d.onset, d.alarm, fold.config.lag_s)
            if onset is not None:
                given = _ours(fitted, tf, onset, onset, 0.0)
    by_evidence = (
        {str(s): named_at(after.over_time, d.alarm + s) for s in CLASS_EVIDENCE_S}
        if d.alarm is not None
        else {}
    )
    return RunResult(
        trial=name,
        label=label,
        onset=onset,
        onset_source=source,
        run_score=float(np.max(d.score)) if len(d.score) else 0.0,
        alarm=d.alarm,
        alarm_signal=d.alarm_signal,
        onset_estimate=d.onset,
        predicted_class=after.last,
        class_by_evidence=by_evidence,
        class_given_onset=given.last,
        directions=after.directions,
        directions_given_onset=given.directions,
        times=d.times,
        score=d.score,
        classes_over_time=after.over_time,
    )


def _method_groups(methods: Sequence[str]) -> list[tuple[str, ...]]:
    """The methods in groups that share fitted parts, the costliest group first: the verifier
    with its mismatch variant and MiniRocket (which names on the verifier's alarms), the HMMs,
    then each baseline alone."""
    shared = tuple(m for m in ("verifier", WITH_MISMATCH, "minirocket") if m in methods)
    rest = [(m,) for m in ("hmm", *METHODS) if m in methods and m not in shared]
    return [g for g in (shared, *rest) if g]


@dataclass(frozen=True)
class _Inputs:
    """What every fold task reads: the trials' features, labels and raw wrench, the settings."""

    feats: Mapping[str, TrialFeatures]
    labels: Mapping[str, TrialLabel]
    raws: Mapping[str, Raw]
    config: VerifyConfig
    seed: int
    contradictions: Mapping[str, Sequence[Contradiction]] | None


def _fold_results(
    k: int, methods: Sequence[str], split: tuple[list[str], list[str]], inputs: _Inputs
) -> tuple[int, dict[str, list[RunResult]]]:
    """Fold `k`'s test runs through `methods` fitted on its training trials, tagged with `k`
    (tasks end in any order; the caller puts the runs back in fold order)."""
    train, test = split
    i = inputs
    fold = _make_fold(train, i.feats, i.labels, i.config, i.seed)
    failed = [n for n in train if i.labels[n].failed]
    _fit_peers(fold, failed, i.raws, [m for m in methods if m in PEERS])
    return k, {
        m: [_run(fold, m, n, i.feats, i.labels, i.raws, i.contradictions) for n in test]
        for m in methods
    }


def _ratio(a: float, b: float) -> float | None:
    return float(a / b) if b else None


def metrics(results: Sequence[RunResult], gate_s: float = GATE_S) -> dict[str, Any]:
    """The protocol's numbers for one method's test runs."""
    failed = [r for r in results if r.label.failed]
    return {
        **_detection_metrics(results, gate_s),
        **_class_metrics(failed),
        **_direction_metrics(failed),
    }


def _detection_metrics(results: Sequence[RunResult], gate_s: float) -> dict[str, Any]:
    """Whether and when each run alarmed: an alarm within `gate_s` after the onset detects."""
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
    return {
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
    }


def _class_metrics(failed: Sequence[RunResult]) -> dict[str, Any]:
    """How often the failure runs were named with their labelled class (overall, per class)."""
    return {
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


def _direction_metrics(failed: Sequence[RunResult]) -> dict[str, Any]:
    """Share of deviated runs whose deviation direction was named right, per axis (none: {})."""
    deviated = [r for r in failed if r.label.directions() is not None]
    if not deviated:
        return {}
    return {
        key: {
            a: _ratio(
                sum(getattr(r, attr).get(a) == r.label.directions()[a] for r in deviated),  # type: ignore[index]
                len(deviated),
            )
            for a in DIRECTION_AXES
        }
        for key, attr in (
            ("direction_accuracy", "directions"),
            ("direction_accuracy_given_onset", "directions_given_onset"),
        )
    }


def _auc(nominal: Sequence[RunResult], failed: Sequence[RunResult]) -> float | None:
    if not nominal or not failed:
        return None
    y = [0] * len(nominal) + [1] * len(failed)
    s = [r.run_score for r in nominal] + [r.run_score for r in failed]
    return float(roc_auc_score(y, s))


def _raw(trial: Trial) -> Raw:
    t = np.asarray(trial.time, dtype=float)
    return t - t[0], np.hstack([np.asarray(trial.wrench[a], dtype=float) for a in trial.arms])


def _splits(
    names: list[str], labels: Mapping[str, TrialLabel], folds: int | None, seed: int
) -> list[tuple[list[str], list[str]]]:
    """Stratified `folds` over the trials (None: leave one trial out)."""
    if folds is None:
        return [([m for m in names if m != n], [n]) for n in names]
    y = [labels[n].failure_class if labels[n].failed else "success" for n in names]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # a class with fewer trials than folds
        kfold = StratifiedKFold(n_splits=folds, shuffle=True, random_state=seed)
        return [([names[i] for i in a], [names[i] for i in b]) for a, b in kfold.split(names, y)]


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
    peers: bool = True,
    jobs: int = 1,
) -> dict[str, list[RunResult]]:
    """Every test run of every method: stratified `folds` over `trials` (None: leave one trial
    out), or fitted on `train` and tested on `trials` (transfer; training trials are kept apart
    from the test trials even when their names are the same, as in two simulated sets).
    `contradictions` (test trial -> the classifier's contradicting final verdicts) adds the
    verifier with the mismatch signal (WITH_MISMATCH); `peers` adds the anchors' methods.
    `jobs`: joblib workers for the trials' features and the folds (the results do not depend
    on it; a joblib backend set by the caller, such as Dask's, is used)."""
    parallel = Parallel(n_jobs=jobs)
    feats = dict(
        zip(
            (t.name for t in trials),
            parallel(delayed(trial_features)(t, config) for t in trials),
            strict=True,
        )
    )
    raws = {t.name: _raw(t) for t in trials} if peers else {}
    labels = dict(labels)
    names = [t.name for t in trials]
    if train:
        keys = [TRAIN_PREFIX + t.name for t in train]
        train_feats = parallel(delayed(trial_features)(t, config) for t in train)
        for key, t, tf in zip(keys, train, train_feats, strict=True):
            feats[key] = tf
            labels[key] = (train_labels or labels)[t.name]
            if peers:
                raws[key] = _raw(t)
        splits = [(keys, names)]
    else:
        splits = _splits(names, labels, folds, seed)
    methods = [*METHODS, *(PEERS if peers else ()), *([WITH_MISMATCH] if contradictions else [])]
    inputs = _Inputs(feats, labels, raws, config, seed, contradictions)
    tasks = [(k, g) for g in _method_groups(methods) for k in range(len(splits))]
    out = Parallel(n_jobs=jobs, return_as="generator_unordered")(
        delayed(_fold_results)(k, g, splits[k], inputs) for k, g in tasks
    )
    by_task: dict[tuple[int, str], list[RunResult]] = {}
    for done, (k, results) in enumerate(out, 1):
        by_task.update({(k, m): res for m, res in results.items()})
        if progress is not None:
            progress(f"fold {k + 1}/{len(splits)}: {', '.join(results)} ({done}/{len(tasks)})")
    return {m: [r for k in range(len(splits)) for r in by_task[k, m]] for m in methods}


def summarise(
    runs: Mapping[str, Sequence[RunResult]], config: VerifyConfig, protocol: str
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The JSON summary (the verifier's numbers, the baselines and anchors beside) and per-run
    records."""
    main = metrics(runs["verifier"])
    sources = [r.onset_source for r in runs["verifier"] if r.label.failed]
    summary: dict[str, Any] = {
        **main,
        "protocol": {
            "folds": protocol,
            "gate_s": GATE_S,
            "false_alarm_rate_target": config.false_alarm_rate,
            "onset_source": {s: sources.count(s) for s in sorted(set(sources))},
            "minirocket": "no detector of its own: named on the verifier's alarms and onsets",
        },
        "baselines": {
            m: metrics(runs[m]) for m in (*METHODS, *PEERS) if m != "verifier" and m in runs
        },
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
            "class_given_onset": r.class_given_onset,
            "directions": r.directions,
        }
        for m in runs
        for r in runs[m]
    ]
    return summary, records

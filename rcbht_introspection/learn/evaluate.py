"""The paper's learning-curve protocol, made honest: repeated random trial permutations.

For each permutation a random set of validation trials is held out; the classifier is trained
on the first 1 (SVM) or 3 (Mondrian) training trials' sub-tasks, then one more trial per step up
to all of them, and scored on the validation sub-tasks. The steady state is the mean of the last
third of the curve. Each permutation's last step is also one random trial split (every trial
holds all four sub-tasks, so the split is stratified by sub-task); the best of those splits is
reported only to compare with the paper's best-of-many-splits figure.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from sklearn.ensemble import RandomForestClassifier

from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar import EncodingName
from rcbht_introspection.grammar.encoding.cache import SampleCache
from rcbht_introspection.grammar.split import SubtaskSample, prefix_sample
from rcbht_introspection.io.sensor_checks import RepeatedPolicy
from rcbht_introspection.learn import ClassifierKind
from rcbht_introspection.learn.data import TrialSamples, load_samples, task_of_trials
from rcbht_introspection.learn.live import load_live_config, stream_factory, trial_live_samples
from rcbht_introspection.learn.models import train_model
from rcbht_introspection.taxonomy.config import TaxonomyConfig

VALIDATION_TRIALS: dict[int, int] = {46: 10, 38: 8, 20: 6}
"""The paper's held-out trial counts by data-set size (REAL 36/10, SIM 30/8, two-arm 14/6)."""
START_TRIALS: dict[str, int] = {"svm": 1, "svm-tuned": 1, "mondrian": 3}
PREFIX_FRACTIONS: tuple[float, ...] = (0.25, 0.5, 0.75)
NEAR_EMPTY_SECONDS = 0.05
"""Sub-tasks shorter than this (REAL S-22..S-46 rotation: 5 ms) are dropped in the variant."""


@dataclass(frozen=True)
class Protocol:
    """Settings of one evaluation run."""

    classifier: ClassifierKind = "svm"
    encoding: EncodingName = "compact"
    permutations: int = 20
    n_validation: int | None = None
    start_trials: int | None = None
    seed: int = 0
    n_estimators: int = 100
    max_nodes: int | None = None
    """Mondrian memory budget: nodes of the whole forest (None: unbounded)."""
    max_points: int | None = None
    """Mondrian memory budget: stored training points (None: unbounded)."""
    near_empty_seconds: float = NEAR_EMPTY_SECONDS
    variant: bool = True
    """Also run the variant without near-empty sub-tasks."""
    augment_prefixes: tuple[float, ...] = ()
    """Also train on these prefixes of every training sub-task (for live use); off by default."""
    prefixes: bool = True
    live_augment: bool = False
    """Score live windows with a live head also trained on the training trials' live windows
    (learn/live.py, config/live.yaml); the curve and verdicts use the complete-sub-task model."""
    live_score: bool = False
    """Score the final model on the validation trials' live windows (live_accuracy)."""
    taxonomy: TaxonomyConfig | None = None
    """Profile of the live windows' words, as the trials' (None: config/live.yaml's)."""
    repeated: RepeatedPolicy | None = None
    """Repeated-stamp policy the live windows' trials are read with, as the trials were."""
    live_config: Path | None = None
    """live_augment settings of the live windows, e.g. their stream profile (None: config/live.yaml)."""


def default_validation(n_trials: int, two_arm: bool = False) -> int:
    """Held-out trial count: the paper's (10 of 46, 8 of 38, 6 of 20), else about 22%."""
    if two_arm and n_trials == 20:
        return 6
    return VALIDATION_TRIALS.get(n_trials, max(1, round(0.22 * n_trials)))


def _log_duration(samples: Sequence[SubtaskSample]) -> np.ndarray:
    return np.log(np.maximum([[s.duration] for s in samples], 1e-3))


def _duration_model(samples: Sequence[SubtaskSample], seed: int) -> RandomForestClassifier:
    """The duration-only reference: RandomForest on the log of the sub-task duration."""
    return RandomForestClassifier(n_estimators=100, random_state=seed).fit(
        _log_duration(samples), [s.subtask for s in samples]
    )


def _accuracy(predicted: Sequence[str], samples: Sequence[SubtaskSample]) -> float:
    if not samples:
        return math.nan
    return float(np.mean([p == s.subtask for p, s in zip(predicted, samples, strict=True)]))


def _mean_std(values: Sequence[float]) -> dict[str, float]:
    arr = np.asarray([v for v in values if not math.isnan(v)], dtype=float)
    if not len(arr):
        return {"mean": math.nan, "std": math.nan}
    return {"mean": float(arr.mean()), "std": float(arr.std())}


def _steady(curve_rows: list[list[float]]) -> list[float]:
    """Per permutation: mean accuracy over the last third of its curve."""
    out = []
    for row in curve_rows:
        tail = row[len(row) - max(1, math.ceil(len(row) / 3)) :]
        out.append(float(np.nanmean(tail)))
    return out


def evaluate(
    trials: Sequence[TrialSamples],
    protocol: Protocol = Protocol(),
    progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Run the protocol; returns the JSON-ready result (keys documented in docs/learning.md)."""
    task = task_of_trials(trials)
    complete = [t for t in trials if t.covers(task)]
    excluded = [t.trial for t in trials if not t.covers(task)]
    names = task.subtasks
    two_arm = any(len(s.words.arms) > 1 for t in complete for s in t.samples[:1])
    n_val = protocol.n_validation or default_validation(len(complete), two_arm)
    start = protocol.start_trials or START_TRIALS[protocol.classifier]
    n_train = len(complete) - n_val
    if n_train < start or n_val < 1:
        raise InputError(
            f"{len(complete)} complete trials are too few for {n_val} validation trials "
            f"and a curve starting at {start} training trials"
        )
    steps = list(range(start, n_train + 1))
    tail_steps = steps[len(steps) - max(1, math.ceil(len(steps) / 3)) :]
    curve = np.full((protocol.permutations, len(steps)), math.nan)
    base_curve = np.full((protocol.permutations, len(steps)), math.nan)
    variant_curve = np.full((protocol.permutations, len(tail_steps)), math.nan)
    variant_base = np.full((protocol.permutations, len(tail_steps)), math.nan)
    final_acc, fit_seconds, predict_ms = [], [], []
    confusion = np.zeros((len(names), len(names)), dtype=int)
    prefix_acc: dict[float, list[float]] = {f: [] for f in PREFIX_FRACTIONS}
    prefix_base: dict[float, list[float]] = {f: [] for f in PREFIX_FRACTIONS}
    near_empty = lambda s: s.duration < protocol.near_empty_seconds  # noqa: E731
    n_near_empty = sum(near_empty(s) for t in complete for s in t.samples)
    live = (
        _live_windows(complete, protocol.taxonomy, protocol.repeated, protocol.live_config)
        if protocol.live_augment or protocol.live_score
        else {}
    )
    live_acc: list[float] = []
    cache = SampleCache()  # every model here encodes the same samples: compute each once

    for perm in range(protocol.permutations):
        rng = np.random.default_rng(protocol.seed + perm)
        order = [complete[i] for i in rng.permutation(len(complete))]
        validation, training = order[:n_val], order[n_val:]
        val_samples = [s for t in validation for s in t.samples]
        val_kept = [s for s in val_samples if not near_empty(s)]
        for j, k in enumerate(steps):
            train_samples = [s for t in training[:k] for s in t.samples]
            began = time.perf_counter()
            model = train_model(
                train_samples, protocol.classifier, protocol.encoding,
                random_state=protocol.seed + perm, n_estimators=protocol.n_estimators,
                max_nodes=protocol.max_nodes, max_points=protocol.max_points,
                augment_prefixes=protocol.augment_prefixes, cache=cache, task=task,
            )  # fmt: skip
            elapsed = time.perf_counter() - began
            curve[perm, j] = _accuracy(model.predict_samples(val_samples), val_samples)
            duration = _duration_model(train_samples, protocol.seed + perm)
            base_curve[perm, j] = _accuracy(
                duration.predict(_log_duration(val_samples)), val_samples
            )
            if protocol.variant and k in tail_steps and n_near_empty:
                kept = [s for s in train_samples if not near_empty(s)]
                variant = train_model(
                    kept, protocol.classifier, protocol.encoding,
                    random_state=protocol.seed + perm, n_estimators=protocol.n_estimators,
                    max_nodes=protocol.max_nodes, max_points=protocol.max_points,
                    augment_prefixes=protocol.augment_prefixes, cache=cache, task=task,
                )  # fmt: skip
                i = tail_steps.index(k)
                variant_curve[perm, i] = _accuracy(variant.predict_samples(val_kept), val_kept)
                vbase = _duration_model(kept, protocol.seed + perm)
                variant_base[perm, i] = _accuracy(vbase.predict(_log_duration(val_kept)), val_kept)
            if progress:
                progress(1)
            if k != n_train:
                continue
            # last step = one random trial split
            fit_seconds.append(elapsed)
            predicted = model.predict_samples(val_samples)
            final_acc.append(_accuracy(predicted, val_samples))
            for p, s in zip(predicted, val_samples, strict=True):
                if p in names and s.subtask in names:
                    confusion[names.index(s.subtask), names.index(p)] += 1
            timings = []
            for s in val_samples[: min(len(val_samples), 12)]:
                t0 = time.perf_counter()
                model.predict_proba_samples([s])
                timings.append(time.perf_counter() - t0)
            predict_ms.append(1000 * float(np.median(timings)))
            if live:
                # running windows: the live head (complete + live windows of the training
                # trials) when augmenting, else the model itself (learn/live.py)
                head = model
                if protocol.live_augment:
                    live_train = train_samples + [s for t in training for s in live[t.trial]]
                    head = train_model(
                        live_train, protocol.classifier, protocol.encoding,
                        random_state=protocol.seed + perm, n_estimators=protocol.n_estimators,
                        max_nodes=protocol.max_nodes, max_points=protocol.max_points,
                        augment_prefixes=protocol.augment_prefixes, cache=cache, task=task,
                    )  # fmt: skip
                windows = [s for t in validation for s in live[t.trial]]
                live_acc.append(_accuracy(head.predict_samples(windows), windows))
            if protocol.prefixes:
                for f in PREFIX_FRACTIONS:
                    prefixes = [prefix_sample(s, f) for s in val_samples]
                    prefix_acc[f].append(_accuracy(model.predict_samples(prefixes), prefixes))
                    prefix_base[f].append(
                        _accuracy(duration.predict(_log_duration(prefixes)), prefixes)
                    )

    rows = confusion.sum(axis=1)
    result: dict[str, Any] = {
        "classifier": protocol.classifier,
        "encoding": protocol.encoding,
        "augment_prefixes": list(protocol.augment_prefixes),
        "permutations": protocol.permutations,
        "n_trials": len(complete),
        "n_validation_trials": n_val,
        "n_training_trials": n_train,
        "excluded_trials": excluded,
        "steady_state_accuracy": _mean_std(_steady(curve.tolist())),
        "steady_state_steps": tail_steps,
        "curve": [
            {"n_train_trials": k, **_mean_std(curve[:, j].tolist())} for j, k in enumerate(steps)
        ],
        "per_class_accuracy": {
            name: (float(confusion[i, i] / rows[i]) if rows[i] else math.nan)
            for i, name in enumerate(names)
        },
        "confusion_matrix": confusion.tolist(),
        "confusion_labels": list(names),
        "task": task.to_dict(),
        "trial_splits": {**_mean_std(final_acc), "n": len(final_acc)},
        "best_of_splits": float(np.nanmax(final_acc)) if final_acc else math.nan,
        "fit_seconds": float(np.mean(fit_seconds)) if fit_seconds else math.nan,
        "predict_ms": float(np.median(predict_ms)) if predict_ms else math.nan,
        "duration_baseline": {
            **_mean_std(_steady(base_curve.tolist())),
            "curve": [
                {"n_train_trials": k, **_mean_std(base_curve[:, j].tolist())}
                for j, k in enumerate(steps)
            ],
        },
        "prefix_accuracy": {
            f"{int(f * 100)}%": {
                **_mean_std(prefix_acc[f]),
                "duration_baseline": _mean_std(prefix_base[f])["mean"],
            }
            for f in PREFIX_FRACTIONS
            if prefix_acc[f]
        },
    }
    if live:
        result["live_augment"] = protocol.live_augment
        result["live_accuracy"] = {**_mean_std(live_acc), "n_windows": sum(map(len, live.values()))}
    if protocol.variant:
        result["without_near_empty"] = {
            "near_empty_seconds": protocol.near_empty_seconds,
            "n_samples_removed": int(n_near_empty),
            "steady_state_accuracy": _mean_std(np.nanmean(variant_curve, axis=1).tolist())
            if n_near_empty
            else result["steady_state_accuracy"],
            "duration_baseline": _mean_std(np.nanmean(variant_base, axis=1).tolist())
            if n_near_empty
            else {k: result["duration_baseline"][k] for k in ("mean", "std")},
        }
    return result


def _live_windows(
    trials: Sequence[TrialSamples],
    taxonomy: TaxonomyConfig | None = None,
    repeated: RepeatedPolicy | None = None,
    live_config: Path | None = None,
) -> dict[str, list[SubtaskSample]]:
    """Live-like windows of every trial (words final by t, learn/live.py), by trial name."""
    config = load_live_config(live_config)
    factory = stream_factory(config, taxonomy)
    by_path = trial_live_samples([t.path for t in trials], config, factory, repeated=repeated)
    return {t.trial: by_path[str(t.path)] for t in trials}


def total_steps(trials: Sequence[TrialSamples], protocol: Protocol) -> int:
    """Number of curve steps `evaluate` will run (for a progress bar)."""
    task = task_of_trials(trials)
    complete = [t for t in trials if t.covers(task)]
    two_arm = any(len(s.words.arms) > 1 for t in complete for s in t.samples[:1])
    n_val = protocol.n_validation or default_validation(len(complete), two_arm)
    start = protocol.start_trials or START_TRIALS[protocol.classifier]
    return max(0, len(complete) - n_val - start + 1) * protocol.permutations


def trial_kfold_accuracy(dataset: Path, folds: int = 4) -> dict[str, object]:
    """Trial-grouped k-fold SVM (compact encoding) accuracy on one dataset folder: a quick check
    that the words of a (simulated) set carry the sub-task; `duration_accuracy` is the
    duration-only reference on the same folds."""
    samples = load_samples([dataset], words="engine")
    trials = sorted({s.trial for s in samples})
    if len(trials) < folds:
        return {"available": False, "why": f"only {len(trials)} trials"}
    correct = by_duration = total = 0
    cache = SampleCache()  # every fold encodes the same samples
    for k in range(folds):
        test = set(trials[k::folds])
        train = [s for s in samples if s.trial not in test]
        held = [s for s in samples if s.trial in test]
        model = train_model(
            train, classifier="svm", encoding="compact", random_state=0, cache=cache
        )
        predicted = model.predict_samples(held)
        correct += sum(p == s.subtask for p, s in zip(predicted, held, strict=True))
        guessed = _duration_model(train, seed=0).predict(_log_duration(held))
        by_duration += sum(p == s.subtask for p, s in zip(guessed, held, strict=True))
        total += len(held)
    return {
        "available": True,
        "folds": folds,
        "samples": total,
        "accuracy": correct / total,
        "duration_accuracy": by_duration / total,
    }

"""The paper's learning-curve protocol, made honest: repeated random trial permutations.

For each permutation a random set of validation trials is held out; the classifier is trained
on the first 1 (SVM) or 3 (Mondrian) training trials' sub-tasks, then one more trial per step up
to all of them, and scored on the validation sub-tasks. The steady state is the mean of the last
third of the curve. Each permutation's last step is also one random trial split (every trial
holds all four sub-tasks, so the split is stratified by sub-task); the best of those splits is
reported only to compare with the paper's best-of-many-splits figure.

Two references are scored on the same permutations, splits and steps: the sub-task duration
alone (duration_baseline) and, with `Protocol.peers`, MiniRocket on each sub-task's raw wrench
(minirocket_baseline, peers/subtask_baseline.py; at the steady-state steps only, as it costs
about a second a fit).
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from sklearn.ensemble import RandomForestClassifier

from rcbht_introspection.errors import InputError
from rcbht_introspection.fleet import parallel_map
from rcbht_introspection.grammar import EncodingName
from rcbht_introspection.grammar.encoding.cache import SampleCache
from rcbht_introspection.grammar.split import SubtaskSample, prefix_sample
from rcbht_introspection.io.sensor_checks import RepeatedPolicy
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.learn import DEFAULT_CLASSIFIER, ClassifierKind
from rcbht_introspection.learn.data import (
    TrialSamples,
    load_samples,
    read_any_trial,
    task_of_trials,
)
from rcbht_introspection.learn.live import load_live_config, stream_factory, trial_live_samples
from rcbht_introspection.learn.models import SubtaskModel, train_model
from rcbht_introspection.task import Task
from rcbht_introspection.taxonomy.config import TaxonomyConfig

if TYPE_CHECKING:
    from rcbht_introspection.peers.subtask_baseline import SubtaskWrench

VALIDATION_TRIALS: dict[int, int] = {46: 10, 38: 8, 20: 6}
"""The paper's held-out trial counts by data-set size (REAL 36/10, SIM 30/8, two-arm 14/6)."""
START_TRIALS: dict[str, int] = {
    "forest": 1,
    "svm-forest": 1,
    "svm": 1,
    "svm-tuned": 1,
    "mondrian": 3,
}
PREFIX_FRACTIONS: tuple[float, ...] = (0.1, 0.25, 0.5, 0.75)
PEER_PREFIXES = PREFIX_FRACTIONS
"""The prefixes MiniRocket's prefix columns are trained on beside whole sub-tasks."""
NEAR_EMPTY_SECONDS = 0.05
"""Sub-tasks shorter than this (REAL S-22..S-46 rotation: 5 ms) are dropped in the variant."""


@dataclass(frozen=True)
class Protocol:
    """Settings of one evaluation run."""

    classifier: ClassifierKind = DEFAULT_CLASSIFIER
    encoding: EncodingName = "words-wrench"
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
    peers: bool = False
    """Also score MiniRocket on the raw wrench (minirocket_baseline); needs the peers extra (aeon):
    check peers.subtask_baseline.aeon_importable() first."""


def default_validation(n_trials: int, two_arm: bool = False) -> int:
    """Held-out trial count: the paper's (10 of 46, 8 of 38, 6 of 20), else about 22%."""
    if two_arm and n_trials == 20:
        return 6
    return VALIDATION_TRIALS.get(n_trials, max(1, round(0.22 * n_trials)))


def _log_duration(samples: Sequence[SubtaskSample]) -> np.ndarray:
    """(n, 1) log sub-task durations (floored at 1 ms): the duration-only reference's feature."""
    logs: NDArray[np.float64] = np.log(np.maximum([[s.duration] for s in samples], 1e-3))
    return logs


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


@dataclass(frozen=True)
class _Plan:
    """The trials and curve steps of one evaluation run."""

    task: Task
    complete: list[TrialSamples]
    """Trials that hold every sub-task of the task (the others are excluded)."""
    excluded: list[str]
    n_val: int
    n_train: int
    steps: list[int]
    """Training trial counts of the curve."""
    tail_steps: list[int]
    """The last third of the steps: the steady state."""


def _plan(trials: Sequence[TrialSamples], protocol: Protocol) -> _Plan:
    """Split sizes and curve steps of `protocol` on `trials` (too few trials is an InputError)."""
    task = task_of_trials(trials)
    complete = [t for t in trials if t.covers(task)]
    excluded = [t.trial for t in trials if not t.covers(task)]
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
    return _Plan(task, complete, excluded, n_val, n_train, steps, tail_steps)


@dataclass
class _Tally:
    """What the permutations measure, filled step by step: curves are (permutation, step)."""

    curve: NDArray[np.float64]
    base_curve: NDArray[np.float64]
    variant_curve: NDArray[np.float64]
    variant_base: NDArray[np.float64]
    confusion: NDArray[np.int_]
    final_acc: list[float] = field(default_factory=list)
    fit_seconds: list[float] = field(default_factory=list)
    predict_ms: list[float] = field(default_factory=list)
    prefix_acc: dict[float, list[float]] = field(
        default_factory=lambda: {f: [] for f in PREFIX_FRACTIONS}
    )
    prefix_base: dict[float, list[float]] = field(
        default_factory=lambda: {f: [] for f in PREFIX_FRACTIONS}
    )
    live_acc: list[float] = field(default_factory=list)
    peer_curve: NDArray[np.float64] = field(default_factory=lambda: np.empty((0, 0)))
    """MiniRocket's accuracy at the steady-state steps (permutation, tail step)."""
    peer_final: list[float] = field(default_factory=list)
    peer_final_samples: list[int] = field(default_factory=list)
    prefix_peer: dict[float, list[float]] = field(
        default_factory=lambda: {f: [] for f in PREFIX_FRACTIONS}
    )

    @classmethod
    def empty(cls, plan: _Plan, permutations: int) -> _Tally:
        """NaN curves (a step not run stays NaN) and an empty confusion matrix."""
        n_names = len(plan.task.subtasks)
        return cls(
            curve=np.full((permutations, len(plan.steps)), math.nan),
            base_curve=np.full((permutations, len(plan.steps)), math.nan),
            variant_curve=np.full((permutations, len(plan.tail_steps)), math.nan),
            variant_base=np.full((permutations, len(plan.tail_steps)), math.nan),
            confusion=np.zeros((n_names, n_names), dtype=int),
            peer_curve=np.full((permutations, len(plan.tail_steps)), math.nan),
        )


class _Run:
    """One evaluation: the protocol and its plan, the live windows, one sample cache shared by
    every model (they all encode the same samples: each is computed once) and the tally."""

    def __init__(
        self,
        protocol: Protocol,
        plan: _Plan,
        live: dict[str, list[SubtaskSample]],
        progress: Callable[[int], None] | None,
    ) -> None:
        self.protocol = protocol
        self.plan = plan
        self.live = live
        self.progress = progress
        self.cache = SampleCache()
        self.tally = _Tally.empty(plan, protocol.permutations)
        self.n_near_empty = _count_near_empty(plan.complete, protocol)
        self.peer: SubtaskWrench | None = None
        self.steps: frozenset[int] | None = None
        """The curve steps (indices) a permutation runs; None: all."""
        if protocol.peers:
            from rcbht_introspection.peers.subtask_baseline import SubtaskWrench

            self.peer = SubtaskWrench(_read_trials(plan.complete, protocol.repeated))

    def near_empty(self, sample: SubtaskSample) -> bool:
        """A sub-task too short to carry words (dropped in the variant)."""
        return sample.duration < self.protocol.near_empty_seconds

    def train(
        self, samples: Sequence[SubtaskSample], perm: int, running: bool = False
    ) -> SubtaskModel:
        """A model of the protocol's classifier and encoding, seeded by the permutation; with
        `running`, also its running head (the one prefixes are scored on)."""
        p = self.protocol
        return train_model(
            samples, p.classifier, p.encoding,
            random_state=p.seed + perm, n_estimators=p.n_estimators,
            max_nodes=p.max_nodes, max_points=p.max_points,
            augment_prefixes=p.augment_prefixes, cache=self.cache, task=self.plan.task,
            running_prefixes=None if running else (),
        )  # fmt: skip

    def permutation(self, perm: int) -> None:
        """One random order of the trials: validation trials first, then a curve that trains
        on one more of the remaining trials per step."""
        plan, tally, seed = self.plan, self.tally, self.protocol.seed + perm
        rng = np.random.default_rng(seed)
        order = [plan.complete[i] for i in rng.permutation(len(plan.complete))]
        validation, training = order[: plan.n_val], order[plan.n_val :]
        val_samples = [s for t in validation for s in t.samples]
        val_kept = [s for s in val_samples if not self.near_empty(s)]
        for j, k in enumerate(plan.steps):
            if self.steps is not None and j not in self.steps:
                continue  # another worker's share of this permutation (_run_permutations)
            train_samples = [s for t in training[:k] for s in t.samples]
            began = time.perf_counter()
            model = self.train(train_samples, perm, running=k == plan.n_train)
            elapsed = time.perf_counter() - began
            tally.curve[perm, j] = _accuracy(model.predict_samples(val_samples), val_samples)
            duration = _duration_model(train_samples, seed)
            tally.base_curve[perm, j] = _accuracy(
                duration.predict(_log_duration(val_samples)), val_samples
            )
            if self.protocol.variant and k in plan.tail_steps and self.n_near_empty:
                self.variant(perm, plan.tail_steps.index(k), train_samples, val_kept)
            if self.peer is not None and k in plan.tail_steps:
                self.peer_step(self.peer, perm, k, train_samples, val_samples)
            if self.progress:
                self.progress(1)
            if k == plan.n_train:  # last step = one random trial split
                self.tally.fit_seconds.append(elapsed)
                self.final_split(model, val_samples)
                self.live_split(perm, model, train_samples, training, validation)
                self.prefix_split(model, duration, val_samples)

    def variant(
        self, perm: int, i: int, train_samples: list[SubtaskSample], val_kept: list[SubtaskSample]
    ) -> None:
        """Steady-state step `i` of the variant: near-empty sub-tasks dropped everywhere."""
        kept = [s for s in train_samples if not self.near_empty(s)]
        variant = self.train(kept, perm)
        self.tally.variant_curve[perm, i] = _accuracy(variant.predict_samples(val_kept), val_kept)
        vbase = _duration_model(kept, self.protocol.seed + perm)
        self.tally.variant_base[perm, i] = _accuracy(
            vbase.predict(_log_duration(val_kept)), val_kept
        )

    def peer_step(
        self,
        peer: SubtaskWrench,
        perm: int,
        k: int,
        train_samples: list[SubtaskSample],
        val_samples: list[SubtaskSample],
    ) -> None:
        """MiniRocket at steady-state step `k` (seeded as the model); at the last step also
        its trial split and, trained on prefixes too (as the running head), its prefixes."""
        model = peer.fit(train_samples, self.protocol.seed + perm)
        accuracy = peer.accuracy(model, val_samples)
        self.tally.peer_curve[perm, self.plan.tail_steps.index(k)] = accuracy
        if k != self.plan.n_train:
            return
        self.tally.peer_final.append(accuracy)
        self.tally.peer_final_samples.append(len(val_samples))
        if self.protocol.prefixes:
            running = peer.fit(train_samples, self.protocol.seed + perm, PEER_PREFIXES)
            for f in PREFIX_FRACTIONS:
                self.tally.prefix_peer[f].append(peer.accuracy(running, val_samples, f))

    def final_split(self, model: SubtaskModel, val_samples: list[SubtaskSample]) -> None:
        """The full-training model as one trial split: accuracy, confusion, prediction time."""
        names = self.plan.task.subtasks
        predicted = model.predict_samples(val_samples)
        self.tally.final_acc.append(_accuracy(predicted, val_samples))
        for p, s in zip(predicted, val_samples, strict=True):
            if p in names and s.subtask in names:
                self.tally.confusion[names.index(s.subtask), names.index(p)] += 1
        timings = []
        for s in val_samples[: min(len(val_samples), 12)]:
            t0 = time.perf_counter()
            model.predict_proba_samples([s])
            timings.append(time.perf_counter() - t0)
        self.tally.predict_ms.append(1000 * float(np.median(timings)))

    def live_split(
        self,
        perm: int,
        model: SubtaskModel,
        train_samples: list[SubtaskSample],
        training: list[TrialSamples],
        validation: list[TrialSamples],
    ) -> None:
        """Accuracy on the validation trials' running windows (when live windows are scored):
        the live head (complete + live windows of the training trials) when augmenting, else
        the model itself (learn/live.py)."""
        if not self.live:
            return
        head = model
        if self.protocol.live_augment:
            live_train = train_samples + [s for t in training for s in self.live[t.trial]]
            head = self.train(live_train, perm)
        windows = [s for t in validation for s in self.live[t.trial]]
        self.tally.live_acc.append(_accuracy(head.predict_samples(windows), windows))

    def prefix_split(
        self,
        model: SubtaskModel,
        duration: RandomForestClassifier,
        val_samples: list[SubtaskSample],
    ) -> None:
        """Accuracy on the first fractions of the validation sub-tasks (when prefixes are on),
        by the head that classifies running windows (model.head(False))."""
        if not self.protocol.prefixes:
            return
        head = model.head(False)
        for f in PREFIX_FRACTIONS:
            prefixes = [prefix_sample(s, f) for s in val_samples]
            self.tally.prefix_acc[f].append(_accuracy(head.predict_samples(prefixes), prefixes))
            self.tally.prefix_base[f].append(
                _accuracy(duration.predict(_log_duration(prefixes)), prefixes)
            )


def _read_trials(
    trials: Sequence[TrialSamples], repeated: RepeatedPolicy | None
) -> dict[str, Trial]:
    """Each sample's trial (its wrench), by the samples' trial name, read with the trial's
    repeated-stamp policy (golden trials: `repeated`, as their live windows are)."""
    out: dict[str, Trial] = {}
    for t in trials:
        trial = read_any_trial(t.path, t.repeated or repeated)
        out.update({s.trial: trial for s in t.samples})
    return out


def _count_near_empty(complete: Sequence[TrialSamples], protocol: Protocol) -> int:
    """Sub-tasks shorter than protocol.near_empty_seconds among the complete trials."""
    return sum(s.duration < protocol.near_empty_seconds for t in complete for s in t.samples)


LAST_STEP_WEIGHT = 3
"""Scheduling estimate only (the results never depend on it): the last step of a permutation
(running heads, trial split, prefixes, live windows) costs about this many ordinary steps."""

Hand = dict[int, frozenset[int]]
"""One worker's units: permutation -> the indices of the curve steps it runs of it."""


def _hand(run: _Run, hand: Hand) -> list[tuple[int, _Tally]]:
    """The hand's steps on one worker's copy of the run, a tally per permutation. The run's
    sample cache is kept throughout, as `--jobs 1` keeps it from permutation to permutation."""
    tallies = []
    for perm, steps in hand.items():
        run.tally = _Tally.empty(run.plan, run.protocol.permutations)
        run.steps = steps
        run.permutation(perm)
        tallies.append((perm, run.tally))
    return tallies


def _deal(run: _Run, workers: int) -> list[Hand]:
    """Every (permutation, step) dealt to at most `workers` hands, the costliest first to the
    least loaded hand; a step's estimated cost is its training set size (LAST_STEP_WEIGHT times
    that for a permutation's last step)."""
    steps, last = run.plan.steps, len(run.plan.steps) - 1
    units = sorted(
        ((k * (LAST_STEP_WEIGHT if j == last else 1), p, j)
         for p in range(run.protocol.permutations) for j, k in enumerate(steps)),
        reverse=True,
    )  # fmt: skip
    n = max(1, min(workers, len(units)))
    load, hands = [0] * n, [dict[int, set[int]]() for _ in range(n)]
    for cost, p, j in units:
        i = load.index(min(load))
        load[i] += cost
        hands[i].setdefault(p, set()).add(j)
    return [{p: frozenset(h[p]) for p in sorted(h)} for h in hands]


def _merge_tally(into: _Tally, part: _Tally) -> None:
    """Add one worker's tally of one permutation: the curve cells it ran, its counts, its list
    entries (merged in permutation order, the lists are those of one process running them in
    turn: only a permutation's last step adds to them)."""
    for f in dataclasses.fields(_Tally):
        mine, theirs = getattr(into, f.name), getattr(part, f.name)
        if isinstance(mine, np.ndarray) and mine.dtype.kind == "f":
            ran = ~np.isnan(theirs)  # curves: (permutation, step), NaN where not run
            mine[ran] = theirs[ran]
        elif isinstance(mine, np.ndarray):
            mine += theirs  # counts
        elif isinstance(mine, list):
            mine.extend(theirs)
        else:  # per prefix fraction: lists
            for key, values in theirs.items():
                mine[key].extend(values)


def _run_permutations(run: _Run, jobs: int) -> None:
    """Every permutation of the protocol into run.tally: in turn (`jobs` 1), else their steps
    dealt to the joblib workers, one hand and one copy of the run per worker
    (fleet.parallel_map); each step is seeded by its permutation, never by its worker, only a
    permutation's last step adds to the tally's lists, and the tallies are merged in permutation
    order: the tally of running them in turn."""
    if jobs == 1:
        for perm in range(run.protocol.permutations):
            run.permutation(perm)
        return
    from joblib import effective_n_jobs

    progress = run.progress
    shipped = copy.copy(run)
    shipped.progress = None  # a progress bar stays in this process
    hands = _deal(run, effective_n_jobs(jobs))
    ticks = iter([sum(map(len, hand.values())) for hand in hands])
    parts = parallel_map(
        functools.partial(_hand, shipped),
        hands,
        jobs,
        (lambda _: progress(next(ticks))) if progress is not None else None,
    )
    for _, tally in sorted((pair for part in parts for pair in part), key=lambda pair: pair[0]):
        _merge_tally(run.tally, tally)


def evaluate(
    trials: Sequence[TrialSamples],
    protocol: Protocol = Protocol(),
    progress: Callable[[int], None] | None = None,
    jobs: int = 1,
) -> dict[str, Any]:
    """Run the protocol; returns the JSON-ready result (keys documented in docs/learning.md).
    `jobs`: joblib workers for the permutations (fleet.py; the result is the same whatever N,
    but for the measured fit and prediction times)."""
    plan = _plan(trials, protocol)
    live = (
        _live_windows(plan.complete, protocol.taxonomy, protocol.repeated, protocol.live_config)
        if protocol.live_augment or protocol.live_score
        else {}
    )
    run = _Run(protocol, plan, live, progress)
    _run_permutations(run, jobs)
    result = _curve_result(plan, protocol, run.tally)
    if live:
        result["live_augment"] = protocol.live_augment
        result["live_accuracy"] = {
            **_mean_std(run.tally.live_acc),
            "n_windows": sum(map(len, live.values())),
        }
    if run.peer is not None:
        _add_peer_result(result, plan, run.tally)
    if protocol.variant:
        result["without_near_empty"] = _variant_result(
            protocol, run.tally, run.n_near_empty, result
        )
    return result


def _step_curve(curve: NDArray[np.float64], steps: list[int]) -> list[dict[str, float]]:
    """Mean and spread over permutations of each curve step."""
    return [{"n_train_trials": k, **_mean_std(curve[:, j].tolist())} for j, k in enumerate(steps)]


def _curve_result(plan: _Plan, protocol: Protocol, tally: _Tally) -> dict[str, Any]:
    """The JSON-ready curve, split, confusion, timing and prefix figures of a finished run."""
    names = plan.task.subtasks
    rows = tally.confusion.sum(axis=1)
    final_acc, fit_seconds, predict_ms = tally.final_acc, tally.fit_seconds, tally.predict_ms
    return {
        "classifier": protocol.classifier,
        "encoding": protocol.encoding,
        "augment_prefixes": list(protocol.augment_prefixes),
        "permutations": protocol.permutations,
        "n_trials": len(plan.complete),
        "n_validation_trials": plan.n_val,
        "n_training_trials": plan.n_train,
        "excluded_trials": plan.excluded,
        "steady_state_accuracy": _mean_std(_steady(tally.curve.tolist())),
        "steady_state_steps": plan.tail_steps,
        "curve": _step_curve(tally.curve, plan.steps),
        "per_class_accuracy": {
            name: (float(tally.confusion[i, i] / rows[i]) if rows[i] else math.nan)
            for i, name in enumerate(names)
        },
        "confusion_matrix": tally.confusion.tolist(),
        "confusion_labels": list(names),
        "task": plan.task.to_dict(),
        "trial_splits": {**_mean_std(final_acc), "n": len(final_acc)},
        "best_of_splits": float(np.nanmax(final_acc)) if final_acc else math.nan,
        "fit_seconds": float(np.mean(fit_seconds)) if fit_seconds else math.nan,
        "predict_ms": float(np.median(predict_ms)) if predict_ms else math.nan,
        "duration_baseline": {
            **_mean_std(_steady(tally.base_curve.tolist())),
            "curve": _step_curve(tally.base_curve, plan.steps),
        },
        "prefix_accuracy": {
            f"{int(f * 100)}%": {
                **_mean_std(tally.prefix_acc[f]),
                "duration_baseline": _mean_std(tally.prefix_base[f])["mean"],
            }
            for f in PREFIX_FRACTIONS
            if tally.prefix_acc[f]
        },
    }


def _add_peer_result(result: dict[str, Any], plan: _Plan, tally: _Tally) -> None:
    """minirocket_baseline beside duration_baseline: its steady state (the mean of each
    permutation's steady-state steps, as the model's), curve at those steps and trial splits
    (`n_subtasks`: validation sub-tasks scored in all); its prefix accuracies beside the
    model's."""
    final = tally.peer_final
    result["minirocket_baseline"] = {
        **_mean_std(np.nanmean(tally.peer_curve, axis=1).tolist()),
        "curve": _step_curve(tally.peer_curve, plan.tail_steps),
        "trial_splits": {**_mean_std(final), "n": len(final)},
        "n_subtasks": int(sum(tally.peer_final_samples)),
    }
    for f in PREFIX_FRACTIONS:
        key = f"{int(f * 100)}%"
        if key in result["prefix_accuracy"] and tally.prefix_peer[f]:
            result["prefix_accuracy"][key]["minirocket_baseline"] = _mean_std(tally.prefix_peer[f])[
                "mean"
            ]


def _variant_result(
    protocol: Protocol, tally: _Tally, n_near_empty: int, result: dict[str, Any]
) -> dict[str, Any]:
    """The steady state without near-empty sub-tasks (the full run's when there are none)."""
    return {
        "near_empty_seconds": protocol.near_empty_seconds,
        "n_samples_removed": int(n_near_empty),
        "steady_state_accuracy": _mean_std(np.nanmean(tally.variant_curve, axis=1).tolist())
        if n_near_empty
        else result["steady_state_accuracy"],
        "duration_baseline": _mean_std(np.nanmean(tally.variant_base, axis=1).tolist())
        if n_near_empty
        else {k: result["duration_baseline"][k] for k in ("mean", "std")},
    }


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


def evaluate_transfer(
    train: Sequence[TrialSamples],
    test: Sequence[TrialSamples],
    protocol: Protocol = Protocol(),
    seeds: int = 5,
) -> dict[str, Any]:
    """One set of recordings scored by a model of another (another day, another session).

    The model (its running head for the prefixes) is trained on every sub-task of `train` and
    scored on every sub-task of `test`, whole and at PREFIX_FRACTIONS, beside the duration-only
    model and, with `protocol.peers`, MiniRocket trained on the same trials; each of `seeds`
    seeds refits the seeded parts (the SVM is deterministic, MiniRocket's kernels are not)."""
    task = task_of_trials([*train, *test])
    test = [_renamed(t, " (test)") for t in test]  # another day may reuse TRAIN's trial names
    train_samples = [s for t in train for s in t.samples]
    test_samples = [s for t in test for s in t.samples]
    if not train_samples or not test_samples:
        raise InputError("--train and the evaluated inputs both need sub-task samples")
    plan = _Plan(task, list(train), [], len(test), len(train), [len(train)], [len(train)])
    run = _Run(protocol, plan, {}, None)
    if run.peer is not None:
        run.peer.raws.update(_raws(test, protocol.repeated))
    tally = run.tally = _Tally.empty(plan, seeds)
    for seed in range(seeds):
        model = run.train(train_samples, seed, running=True)
        tally.curve[seed, 0] = _accuracy(model.predict_samples(test_samples), test_samples)
        duration = _duration_model(train_samples, protocol.seed + seed)
        tally.base_curve[seed, 0] = _accuracy(
            duration.predict(_log_duration(test_samples)), test_samples
        )
        run.final_split(model, test_samples)
        run.prefix_split(model, duration, test_samples)
        if run.peer is not None:
            run.peer_step(run.peer, seed, len(train), train_samples, test_samples)
    result = _curve_result(plan, replace(protocol, permutations=seeds), tally)
    result.update(protocol="transfer", n_test_trials=len(test), accuracy=result["trial_splits"])
    for key in ("n_validation_trials", "steady_state_accuracy", "steady_state_steps", "curve"):
        result.pop(key)
    if run.peer is not None:
        _add_peer_result(result, plan, tally)
        result["minirocket_baseline"].pop("curve")
    return result


def _renamed(trial: TrialSamples, suffix: str) -> TrialSamples:
    """The trial with `suffix` on its samples' trial name (their wrench is looked up by it)."""
    samples = [replace(s, trial=s.trial + suffix) for s in trial.samples]
    return replace(trial, samples=samples)


def _raws(trials: Sequence[TrialSamples], repeated: RepeatedPolicy | None) -> Any:
    """The raw wrench of `trials` for MiniRocket (peers/subtask_baseline.raw_wrench), by name."""
    from rcbht_introspection.peers.subtask_baseline import raw_wrench

    return {name: raw_wrench(trial) for name, trial in _read_trials(trials, repeated).items()}

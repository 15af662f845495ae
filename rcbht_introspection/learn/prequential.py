"""The prequential protocol: trials taught one by one through OnlineLearner (the node's path).

The last `held_out` trials in recording order are never taught; the others are taught in
recording order and in `permutations` shuffled orders. After 1, 2, 5, 10, 20 taught trials the
online model is scored on the held-out trials beside a batch Mondrian model (train_model on the
same trials, windows and prefixes), an SVM retrained on the same samples (the reference) and
the duration-only baseline. Each trial is also predicted before it is taught (test-then-train).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar import EncodingName
from rcbht_introspection.grammar.encoding.cache import SampleCache
from rcbht_introspection.grammar.split import SubtaskSample
from rcbht_introspection.learn.data import TrialSamples, task_of_trials
from rcbht_introspection.learn.evaluate import (
    _accuracy,
    _duration_model,
    _log_duration,
    default_validation,
)
from rcbht_introspection.learn.models import SubtaskModel, train_model
from rcbht_introspection.learn.online import OnlineLearner, TeachConfig
from rcbht_introspection.task import Task

STEPS: tuple[int, ...] = (1, 2, 5, 10, 20)
"""Numbers of taught trials at which the models are scored (those <= the training trials)."""
PERMUTATIONS = 4
"""Default shuffled teaching orders (besides the recording order)."""


@dataclass(frozen=True)
class PrequentialProtocol:
    """Settings of one prequential run."""

    teach: TeachConfig = field(default_factory=TeachConfig)
    permutations: int = PERMUTATIONS
    """Shuffled teaching orders besides the recording order."""
    held_out: int | None = None
    """The last this many trials in recording order are scored, never taught (None: ~22%,
    10 of 46 as the curve protocol holds out)."""
    steps: tuple[int, ...] = STEPS
    seed: int = 0
    svm: bool = True
    """Also retrain the SVM reference at each step."""


@dataclass
class _Scores:
    """Accuracy per order (rows) and step (columns) of each model."""

    online: np.ndarray
    batch: np.ndarray
    svm: np.ndarray
    duration: np.ndarray
    running: np.ndarray
    """Test-then-train accuracy over trials 2..k (each predicted before it was taught)."""


def split_trials(
    trials: Sequence[TrialSamples], task: Task, held_out: int | None
) -> tuple[list[TrialSamples], list[TrialSamples]]:
    """(teaching pool, held-out trials): complete trials, the last `held_out` held out."""
    complete = [t for t in trials if t.covers(task)]
    n_held = held_out if held_out is not None else default_validation(len(complete))
    if n_held < 1 or len(complete) - n_held < 1:
        raise InputError(
            f"{len(complete)} complete trials are too few to hold out {n_held} and teach any"
        )
    return complete[:-n_held], complete[-n_held:]


def _teaching_order(
    pool: Sequence[TrialSamples], order_index: int, seed: int
) -> list[TrialSamples]:
    """Order 0 is the recording order; order i > 0 a permutation drawn with seed + i."""
    if order_index == 0:
        return list(pool)
    rng = np.random.default_rng(seed + order_index)
    return [pool[i] for i in rng.permutation(len(pool))]


class _Teaching:
    """One prequential run: teaches every order and fills the scores and the teach timings."""

    def __init__(
        self,
        protocol: PrequentialProtocol,
        task: Task,
        steps: list[int],
        held: Sequence[TrialSamples],
        progress: Callable[[int], None] | None,
    ) -> None:
        self.protocol = protocol
        self.task = task
        self.steps = steps
        self.held_samples = [s for t in held for s in t.samples]
        self.progress = progress
        self.n_orders = 1 + protocol.permutations
        shape = (self.n_orders, len(steps))
        self.scores = _Scores(*(np.full(shape, math.nan) for _ in range(5)))
        self.cache = SampleCache()  # batch, SVM and duration models encode the same samples
        self.timing: dict[str, list[float]] = {"refit": [], "extend": [], "copy": [], "batch": []}

    def teach_order(self, order_index: int, order: list[TrialSamples]) -> None:
        """Teach `order` trial by trial, each predicted first (test-then-train); score the
        models at the steps."""
        seed = self.protocol.seed + order_index
        learner = OnlineLearner(self.protocol.teach, task=self.task, random_state=seed)
        correct = seen = 0
        for n_taught, trial in enumerate(order, start=1):
            if learner.model is not None:
                predicted = learner.model.predict_samples(trial.samples)
                correct += sum(
                    p == s.subtask for p, s in zip(predicted, trial.samples, strict=True)
                )
                seen += len(trial.samples)
            warm = learner.warming_up
            t0 = time.perf_counter()
            model = learner.teach(trial.samples)
            self.timing["refit" if warm else "extend"].append(time.perf_counter() - t0)
            if not warm:
                self.timing["copy"].append(learner.last_copy_s)
            if self.progress:
                self.progress(1)
            if n_taught in self.steps:
                taught = [s for t in order[:n_taught] for s in t.samples]
                running = correct / seen if seen else math.nan
                self.score_step(order_index, self.steps.index(n_taught), model, taught, running)

    def score_step(
        self,
        order_index: int,
        j: int,
        model: SubtaskModel,
        taught: list[SubtaskSample],
        running: float,
    ) -> None:
        """Held-out accuracy at step j of the online model, a batch Mondrian and an SVM
        trained on the same samples, and the duration-only baseline."""
        held, scores, seed = self.held_samples, self.scores, self.protocol.seed + order_index
        scores.online[order_index, j] = _accuracy(model.predict_samples(held), held)
        scores.running[order_index, j] = running
        t0 = time.perf_counter()
        batch = _batch(taught, "mondrian", self.protocol.teach, seed, self.task, self.cache)
        self.timing["batch"].append(time.perf_counter() - t0)
        scores.batch[order_index, j] = _accuracy(batch.predict_samples(held), held)
        if self.protocol.svm:
            svm = _batch(taught, "svm", self.protocol.teach, seed, self.task, self.cache)
            scores.svm[order_index, j] = _accuracy(svm.predict_samples(held), held)
        duration = _duration_model(taught, seed)
        scores.duration[order_index, j] = _accuracy(duration.predict(_log_duration(held)), held)


def prequential(
    trials: Sequence[TrialSamples],
    protocol: PrequentialProtocol = PrequentialProtocol(),
    progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Run the protocol; returns the JSON-ready result (keys documented in docs/learning.md)."""
    began = time.perf_counter()
    task = task_of_trials(trials)
    pool, held = split_trials(trials, task, protocol.held_out)
    steps = [k for k in protocol.steps if 1 <= k <= len(pool)]
    if not steps:
        raise InputError(f"no step of {list(protocol.steps)} fits {len(pool)} teaching trials")
    run = _Teaching(protocol, task, steps, held, progress)
    for order_index in range(run.n_orders):
        run.teach_order(order_index, _teaching_order(pool, order_index, protocol.seed))
    result: dict[str, Any] = {
        "protocol": "prequential",
        "classifier": "mondrian",
        "encoding": protocol.teach.encoding,
        "teach": {
            "warmup_windows": protocol.teach.warmup_windows,
            "prefixes": list(protocol.teach.prefixes),
            "n_estimators": protocol.teach.n_estimators,
        },
        "steps": steps,
        "orders": run.n_orders,
        "permutations": protocol.permutations,
        "n_trials": len(pool) + len(held),
        "n_training_trials": len(pool),
        "held_out_trials": [t.trial for t in held],
        "excluded_trials": [t.trial for t in trials if not t.covers(task)],
        "task": task.to_dict(),
        "seconds": time.perf_counter() - began,
        "teach_seconds": {k: _mean(v) for k, v in run.timing.items() if k != "batch"},
        "batch_fit_seconds": _mean(run.timing["batch"]),
    }
    result.update(_score_tables(run.scores))
    return result


def _score_tables(scores: _Scores) -> dict[str, Any]:
    """The JSON-ready accuracy tables: per model the mean and spread per step over the orders,
    the online and batch accuracy of each order, and the test-then-train curve."""
    result: dict[str, Any] = {}
    for key, table in (
        ("prequential", scores.online),
        ("batch", scores.batch),
        ("svm", scores.svm),
        ("duration", scores.duration),
    ):
        result[f"{key}_accuracy"] = _column_means(table)
        result[f"{key}_std"] = _column_stds(table)
    result["per_order"] = {
        "prequential": _rows(scores.online),
        "batch": _rows(scores.batch),
        "note": "rows = teaching orders (0 = recording order), columns = steps",
    }
    result["test_then_train_accuracy"] = {
        "curve": _column_means(scores.running),
        "std": _column_stds(scores.running),
        "note": "each trial predicted by the model taught on the trials before it "
        "(trials 2..k of each order; the first has no model yet)",
    }
    return result


def _batch(
    samples: Sequence[SubtaskSample],
    classifier: str,
    teach: TeachConfig,
    seed: int,
    task: Task,
    cache: SampleCache,
) -> Any:
    """A model trained from scratch on the taught windows and their prefixes."""
    encoding: EncodingName = "paper" if teach.encoding == "paper" else "compact"
    return train_model(
        samples,
        "mondrian" if classifier == "mondrian" else "svm",
        encoding,
        random_state=seed,
        n_estimators=teach.n_estimators,
        augment_prefixes=teach.prefixes,
        cache=cache,
        task=task,
    )


def _mean(values: Sequence[float]) -> float:
    return float(np.mean(values)) if len(values) else math.nan


def _rows(table: np.ndarray) -> list[list[float]]:
    return [[float(v) for v in row] for row in table]


def _column_means(table: np.ndarray) -> list[float]:
    return [_nan_stat(np.nanmean, table[:, j]) for j in range(table.shape[1])]


def _column_stds(table: np.ndarray) -> list[float]:
    return [_nan_stat(np.nanstd, table[:, j]) for j in range(table.shape[1])]


def _nan_stat(stat: Callable[[np.ndarray], Any], column: np.ndarray) -> float:
    """The statistic over the non-NaN entries (NaN when there are none)."""
    if np.isnan(column).all():
        return math.nan
    return float(stat(column))


def total_teaches(trials: Sequence[TrialSamples], protocol: PrequentialProtocol) -> int:
    """Number of teaches `prequential` runs (for a progress bar)."""
    pool, _ = split_trials(trials, task_of_trials(trials), protocol.held_out)
    return len(pool) * (1 + protocol.permutations)


__all__ = ["STEPS", "PrequentialProtocol", "prequential", "split_trials", "total_teaches"]

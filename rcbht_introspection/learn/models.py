"""Sub-task models: a fitted encoding + classifier (SVM as in the paper, our Mondrian forest).

The classifiers live in svm.py and mondrian.py, the safe model file in model_file.py.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar import EncodingName
from rcbht_introspection.grammar.encoding.axes import AxisMemo
from rcbht_introspection.grammar.encoding.cache import SampleCache
from rcbht_introspection.grammar.encoding.registry import AnyEncoding, make_encoding
from rcbht_introspection.grammar.split import SubtaskSample, prefix_sample
from rcbht_introspection.learn import (
    CLASSIFIERS,
    DEFAULT_CLASSIFIER,
    ClassifierKind,
    running_classifier_of,
)
from rcbht_introspection.learn.forest import ForestHead
from rcbht_introspection.learn.mondrian import MondrianForestClassifier
from rcbht_introspection.learn.svm import fit_svm, make_svm, svm_predict_proba, tune_svm
from rcbht_introspection.learn.vote import SvmForestClassifier
from rcbht_introspection.task import HIRO_TASK, Task, task_of_names
from rcbht_introspection.taxonomy.config import TaxonomyConfig, taxonomy_digest


@dataclass
class SubtaskModel:
    """A fitted encoding + classifier mapping sub-task samples to sub-task probabilities."""

    classifier: str
    encoder: AnyEncoding
    estimator: Any
    taxonomy_profile: str = "reference"
    random_state: int = 0
    training: dict[str, Any] = field(default_factory=dict)
    """How it was trained, stored in the header (e.g. live_augment settings, learn/live.py)."""
    task: Task = HIRO_TASK
    """The task it knows: its sub-task names in order and the phases that end a trial."""
    live: SubtaskModel | None = None
    """Optional head for running (unfinished) windows, trained with live-like windows
    (learn/live.py); final verdicts on finished sub-tasks always use this model itself."""
    window: SubtaskModel | None = None
    """Optional head for window-mode windows [t - window_s, t] (learn/live.py)."""
    taxonomy_sha256: str = ""
    """taxonomy.config.taxonomy_digest of the profile its words came from ('' in older files)."""
    taxonomy: TaxonomyConfig | None = None
    """The profile its words came from, embedded in the model file; given, taxonomy_profile and
    taxonomy_sha256 are its name and digest (None: older files, a cold-started taught model)."""
    takes_axis_memo: ClassVar[bool] = True
    """Its predict calls take `memo=` (an AxisMemo): the belief tracker passes the one it owns
    for its running windows (other models it is given need not)."""

    def __post_init__(self) -> None:
        """The recorded name and digest are those of the embedded profile, when there is one."""
        if self.taxonomy is not None:
            self.taxonomy_profile = self.taxonomy.profile
            self.taxonomy_sha256 = taxonomy_digest(self.taxonomy)

    def head(self, final: bool, mode: str = "boundary") -> SubtaskModel:
        """The model for a finished sub-task (final) or a running window: in window mode the
        window head if any, else the live head if any."""
        if final:
            return self
        if mode == "window" and self.window is not None:
            return self.window
        return self if self.live is None else self.live

    @property
    def reads_wrench(self) -> bool:
        """Its features hold the wrench summary (a running window needs blocks of its own)."""
        return self.encoder.name == "words-wrench"

    @property
    def encoding(self) -> str:
        """Name of the encoding ('paper' or 'compact')."""
        return self.encoder.name

    @property
    def classes_(self) -> list[str]:
        """Sub-task names in the column order of predict_proba_samples."""
        return [str(c) for c in self.estimator.classes_]

    def features(
        self, samples: Sequence[SubtaskSample], memo: AxisMemo | None = None
    ) -> np.ndarray:
        """The encoded samples; `memo`: they are running windows of the memo owner's stream."""
        return self.encoder.transform(samples, memo)

    def predict_proba_samples(
        self, samples: Sequence[SubtaskSample], memo: AxisMemo | None = None
    ) -> np.ndarray:
        """(n, k) class probabilities, columns in classes_ order."""
        return svm_predict_proba(self.estimator, self.features(samples, memo))

    def predict_samples(
        self, samples: Sequence[SubtaskSample], memo: AxisMemo | None = None
    ) -> list[str]:
        """The predicted sub-task of each sample."""
        return [str(c) for c in self.estimator.predict(self.features(samples, memo))]

    def partial_fit_samples(self, samples: Sequence[SubtaskSample]) -> SubtaskModel:
        """Online update with a mini-batch (Mondrian only; the encoding stays as fitted)."""
        if self.classifier != "mondrian":
            raise InputError(f"partial_fit needs the mondrian classifier, not {self.classifier}")
        self.estimator.partial_fit(self.features(samples), [s.subtask for s in samples])
        return self


RUNNING_PREFIXES: dict[str, tuple[float, ...]] = {"words-wrench": (0.1, 0.25, 0.5, 0.75)}
"""Per encoding, the prefixes its running head is trained on beside whole sub-tasks (none: no
running head from train_model; rcbht train may still add a live head, learn/live.py)."""


VERDICT_TREES = 300
"""Trees of the `forest` classifier: it names a sub-task once, when it has ended, so its size
costs nothing live, and more trees only lower the variance of its vote (`n_estimators` sizes the
forests that run at every word: the vote's and Mondrian's)."""


def train_model(
    samples: Sequence[SubtaskSample],
    classifier: ClassifierKind = DEFAULT_CLASSIFIER,
    encoding: EncodingName = "words-wrench",
    random_state: int = 0,
    taxonomy_profile: str = "reference",
    n_estimators: int = 100,
    augment_prefixes: Sequence[float] = (),
    cache: SampleCache | None = None,
    task: Task | None = None,
    taxonomy_sha256: str = "",
    max_nodes: int | None = None,
    max_points: int | None = None,
    running_prefixes: Sequence[float] | None = None,
    taxonomy: TaxonomyConfig | None = None,
) -> SubtaskModel:
    """Fit the encoding and the classifier on `samples` (training data only).

    `augment_prefixes` (e.g. (0.25, 0.5, 0.75)) also trains on those first fractions of every
    sub-task, so a live classifier is not surprised by a sub-task that has only just begun.
    `running_prefixes` (None: RUNNING_PREFIXES of the encoding) trains a running head
    (`model.live`, running_classifier_of(classifier)) on the whole sub-tasks and these prefixes;
    the model itself, which gives final verdicts, stays on whole sub-tasks.
    `cache`: a SampleCache shared by models trained on the same samples (else the encoding's own).
    `n_estimators`: trees of the vote's and the Mondrian forest (`forest` has VERDICT_TREES);
    `max_nodes`, `max_points`: the Mondrian forest's memory budget (None: unbounded).
    `taxonomy`: the profile the samples' words came from (SubtaskModel.taxonomy).
    """
    if classifier not in CLASSIFIERS:
        raise InputError(f"unknown classifier {classifier!r} (known: {', '.join(CLASSIFIERS)})")
    if not samples:
        raise InputError("no training samples")
    task = task or task_of_samples(samples)
    if running_prefixes is None:
        running_prefixes = RUNNING_PREFIXES.get(encoding, ())
    if running_prefixes:
        model = train_model(
            samples, classifier, encoding, random_state, taxonomy_profile, n_estimators,
            augment_prefixes, cache, task, taxonomy_sha256, max_nodes, max_points, (), taxonomy,
        )  # fmt: skip
        running = running_classifier_of(classifier)
        model.live = train_model(
            samples, running, encoding, random_state, taxonomy_profile, n_estimators,
            tuple(augment_prefixes) + tuple(running_prefixes), cache, task, taxonomy_sha256,
            max_nodes, max_points, (), taxonomy,
        )  # fmt: skip
        return model
    samples = with_prefixes(samples, augment_prefixes)
    encoder = make_encoding(encoding, cache).fit(samples)
    X = encoder.transform(samples)
    y = [s.subtask for s in samples]
    budget = (n_estimators, max_nodes, max_points)
    estimator = _fit_classifier(classifier, X, y, samples, task, random_state, budget)
    return SubtaskModel(
        classifier, encoder, estimator, taxonomy_profile, random_state, task=task,
        taxonomy_sha256=taxonomy_sha256, taxonomy=taxonomy,
    )  # fmt: skip


def _fit_classifier(
    classifier: ClassifierKind,
    X: np.ndarray,
    y: list[str],
    samples: Sequence[SubtaskSample],
    task: Task,
    random_state: int,
    budget: tuple[int, int | None, int | None],
) -> Any:
    """The fitted classifier of kind `classifier` on the encoded samples; `budget`: trees,
    nodes and points of the Mondrian forest (trees also of the vote's forest)."""
    n_estimators, max_nodes, max_points = budget
    if classifier != "mondrian" and len(set(y)) < 2:
        raise InputError(f"the {classifier} classifier needs samples of at least two sub-tasks")
    if classifier == "svm-forest":
        return SvmForestClassifier(n_estimators, random_state).fit(X, y)
    if classifier == "forest":
        forest = ForestHead(VERDICT_TREES, min_samples_leaf=1, random_state=random_state)
        return forest.fit(X, y)
    if classifier in ("svm", "svm-tuned"):
        svm = make_svm(random_state)
        if classifier == "svm-tuned":
            svm.set_params(**tune_svm(X, y, [s.trial for s in samples], random_state))
        return fit_svm(svm, X, y)
    classes = sorted(set(task.subtasks) | set(y))
    estimator = MondrianForestClassifier(
        n_estimators=n_estimators,
        random_state=random_state,
        max_nodes=max_nodes,
        max_points=max_points,
    )
    estimator.partial_fit(X, y, classes=classes)
    return estimator


def with_prefixes(
    samples: Sequence[SubtaskSample], fractions: Sequence[float]
) -> list[SubtaskSample]:
    """The samples, then their first `fractions` of each (fraction by fraction): what a model
    that must recognise a sub-task that has only just begun is trained on."""
    samples = list(samples)
    return samples + [prefix_sample(s, f) for f in fractions for s in samples]


def task_of_samples(samples: Sequence[SubtaskSample]) -> Task:
    """The task the samples show: their sub-task names, in the order the trials run them."""
    per_trial: dict[str, list[str]] = {}
    for s in samples:
        per_trial.setdefault(s.trial, []).append(s.subtask)
    return task_of_names(per_trial.values())


__all__ = [
    "RUNNING_PREFIXES",
    "VERDICT_TREES",
    "SubtaskModel",
    "task_of_samples",
    "train_model",
    "with_prefixes",
]

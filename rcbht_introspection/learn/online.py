"""Online learning of labelled windows (pure core): OnlineLearner turns taught windows into models.

STAND-IN with the interface agreed for issue 14 (wt-online builds the real module): it refits
the encoding and the Mondrian forest from scratch on every window kept (and its prefixes) while
at most `warmup_windows` were taught, and extends a copy of the forest with partial_fit after
that. Each `teach` returns a new SubtaskModel; a model already returned is never changed.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from rcbht_introspection.config_files import load_config
from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar import EncodingName
from rcbht_introspection.grammar.split import SubtaskSample, prefix_sample
from rcbht_introspection.learn.models import SubtaskModel, task_of_samples, train_model
from rcbht_introspection.task import Task


@dataclass(frozen=True)
class TeachConfig:
    """How taught windows are learned (section `teach` of a YAML file)."""

    warmup_windows: int = 200
    """Taught windows kept to refit encoding + forest from scratch; then the encoding is frozen."""
    prefixes: tuple[float, ...] = (0.25, 0.5, 0.75)
    """Also teach these first fractions of each window (live-like samples)."""
    n_estimators: int = 100
    encoding: EncodingName = "compact"


def load_teach_config(path: Path | str) -> TeachConfig:
    """The `teach` section of a YAML file."""
    return load_config(TeachConfig, path, section=("teach",))


class OnlineLearner:
    """Learns labelled windows one batch at a time; each batch gives a new model snapshot."""

    def __init__(
        self,
        config: TeachConfig,
        model: SubtaskModel | None = None,
        task: Task | None = None,
        random_state: int = 0,
    ) -> None:
        if model is not None and model.classifier != "mondrian":
            raise InputError(
                f"teaching needs a Mondrian forest model, not {model.classifier!r}", field="model"
            )
        self.config = config
        self._model = model
        self.task = task if task is not None else (model.task if model is not None else None)
        self.random_state = random_state
        self.kept: list[SubtaskSample] = []
        self.taught_windows = 0

    @property
    def model(self) -> SubtaskModel | None:
        """The latest snapshot (None before the first teach and without a starting model)."""
        return self._model

    def teach(self, samples: Sequence[SubtaskSample]) -> SubtaskModel:
        """Learn labelled windows (any new label accepted); return a NEW model."""
        samples = list(samples)
        if not samples:
            raise InputError("nothing to teach (no windows)")
        self.kept.extend(samples)
        task = self._task(samples)
        old = self._model
        new_class = old is not None and not {s.subtask for s in samples} <= set(old.classes_)
        if old is None or new_class or len(self.kept) <= self.config.warmup_windows:
            if old is not None and len(self.kept) == len(samples):
                raise InputError(  # a loaded model whose windows are not kept here
                    "the stand-in learner cannot add a class to a loaded model"
                )
            model = train_model(
                self.kept,
                "mondrian",
                self.config.encoding,
                random_state=self.random_state,
                n_estimators=self.config.n_estimators,
                augment_prefixes=self.config.prefixes,
                task=task,
                taxonomy_profile=old.taxonomy_profile if old is not None else "reference",
                taxonomy_sha256=old.taxonomy_sha256 if old is not None else "",
            )
        else:
            model = copy.deepcopy(old)
            model.live = None
            batch = samples + [prefix_sample(s, f) for f in self.config.prefixes for s in samples]
            model.partial_fit_samples(batch)
            model.task = task
        self._model = model
        self.taught_windows += len(samples)
        return model

    def _task(self, samples: Sequence[SubtaskSample]) -> Task:
        """The task so far, grown by the names of `samples` (new ones after the known ones)."""
        if self.task is None:
            self.task = task_of_samples(samples)
        names = [s.subtask for s in samples if s.subtask not in self.task.subtasks]
        if names:
            self.task = Task(
                (*self.task.subtasks, *dict.fromkeys(names)), self.task.end_phases, self.task.name
            )
        return self.task


__all__ = ["OnlineLearner", "TeachConfig", "load_teach_config"]

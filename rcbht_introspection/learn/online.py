"""Online teaching: the one path by which labelled windows reach a sub-task model (node, CLI,
prequential evaluation).

Cold start (the compact encoding is fitted on data, and a growing Mondrian forest needs fixed
feature bounds): while fewer than `warmup_windows` windows were taught, the learner keeps every
taught window and refits encoding + forest from all of them at each teach (exactly train_model,
batch training); after that the encoding is frozen, the kept windows are dropped and the forest
is only extended with partial_fit. A model given to the learner (e.g. loaded from a file)
continues with partial_fit. Each teach returns a new snapshot; a snapshot is never changed.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, cast

from rcbht_introspection.config_files import config_path, load_config
from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar import ENCODINGS, EncodingName
from rcbht_introspection.grammar.encoding.cache import SampleCache
from rcbht_introspection.grammar.encoding.registry import with_cache
from rcbht_introspection.grammar.split import SubtaskSample
from rcbht_introspection.learn.models import (
    SubtaskModel,
    task_of_samples,
    train_model,
    with_prefixes,
)
from rcbht_introspection.task import Task

TEACH_CONFIG_FILE = "teach.yaml"
ONLINE_KEY = "online"
"""Key of the model's `training` header that records the teaching state."""


LEARNERS = ("process", "thread")
"""Where taught windows are learned (TeachConfig.learner)."""


@dataclass(frozen=True)
class TeachConfig:
    """How taught windows become a model (config/teach.yaml, section teach)."""

    warmup_windows: int = 40
    """Teaches refit encoding + forest from all taught windows until this many were taught;
    then the encoding is frozen and the forest grows with partial_fit only."""
    prefixes: tuple[float, ...] = (0.25, 0.5, 0.75)
    """Also teach these first fractions of each window (what a live classifier sees early)."""
    n_estimators: int = 100
    """Mondrian trees."""
    encoding: str = "compact"
    """Encoding fitted during warm-up ('compact' or 'paper')."""
    max_nodes: int | None = 50000
    """Memory budget of the taught forest: nodes of all trees (None: unbounded; docs/learning.md,
    "Memory budget of the Mondrian forest")."""
    max_points: int | None = 5000
    """... and training points it stores for regrowing leaves (None: unbounded)."""
    learner: str = "process"
    """Where the classifier node learns: 'process' (a process of its own, so learning never
    holds the live path's GIL) or 'thread' (a thread of the node's process)."""


def _check(cfg: TeachConfig) -> None:
    """Ranges beyond the field types (the loader adds file and line to the error)."""
    if cfg.warmup_windows < 0:
        raise InputError(f"must be >= 0, got {cfg.warmup_windows}", field="warmup_windows")
    if cfg.n_estimators < 1:
        raise InputError(f"must be >= 1, got {cfg.n_estimators}", field="n_estimators")
    if cfg.encoding not in ENCODINGS:
        raise InputError(
            f"unknown encoding {cfg.encoding!r} (known: {', '.join(ENCODINGS)})", field="encoding"
        )
    if cfg.max_nodes is not None and cfg.max_nodes < cfg.n_estimators:
        raise InputError(
            f"must be >= n_estimators ({cfg.n_estimators}: one root per tree), got {cfg.max_nodes}",
            field="max_nodes",
        )
    if cfg.learner not in LEARNERS:
        raise InputError(
            f"unknown learner {cfg.learner!r} (known: {', '.join(LEARNERS)})", field="learner"
        )
    if cfg.max_points is not None and cfg.max_points < 0:
        raise InputError(f"must be >= 0, got {cfg.max_points}", field="max_points")
    for i, f in enumerate(cfg.prefixes):
        if not 0 < f <= 1:
            raise InputError(f"must be in (0, 1], got {f}", field=f"prefixes[{i}]")


def load_teach_config(path: Path | str | None = None) -> TeachConfig:
    """The teach section of config/teach.yaml (or of `path`)."""
    file = Path(path) if path is not None else config_path(TEACH_CONFIG_FILE)
    return load_config(TeachConfig, file, section=("teach",), check=_check)


class OnlineLearner:
    """Teaches labelled windows to a Mondrian sub-task model and hands out snapshots.

    Not thread-safe itself: one teaching thread calls `teach`; any number of threads may
    predict with snapshots it returned (they share nothing the learner changes later).
    """

    def __init__(
        self,
        config: TeachConfig,
        model: SubtaskModel | None = None,
        task: Task | None = None,
        random_state: int = 0,
        taxonomy_profile: str = "reference",
        taxonomy_sha256: str = "",
    ) -> None:
        _check(config)
        self.taxonomy_profile = taxonomy_profile
        self.taxonomy_sha256 = taxonomy_sha256
        """The profile (and digest) the taught words come from: recorded in a cold-started model."""
        self.config = config
        self.task = task
        self.random_state = random_state
        self.taught_windows = 0
        """Windows taught so far (prefix windows not counted), including those of a given model."""
        self.refits = 0
        self.taught_live = 0
        """Live-like windows taught beside the windows (learn/teaching.py takes them)."""
        """Teaches that refitted encoding + forest from the kept windows (warm-up)."""
        self.last_copy_s = 0.0
        """Seconds the last teach spent copying the forest so the previous snapshot stays intact."""
        self._kept: list[SubtaskSample] = []
        self._kept_live: list[SubtaskSample] = []
        self._cache = SampleCache()
        self._working: SubtaskModel | None = None
        self._shared = False
        """The working forest is also the latest snapshot's: copy it before changing it."""
        self._snapshot: SubtaskModel | None = None
        if model is not None:
            _require_mondrian(model)
            state = model.training.get(ONLINE_KEY) or {}
            self.taught_windows = int(state.get("taught_windows", 0))
            self.task = task or model.task
            self.taxonomy_profile = model.taxonomy_profile
            self.taxonomy_sha256 = model.taxonomy_sha256
            self._working = model
            self._snapshot = model
            self._shared = True

    @property
    def model(self) -> SubtaskModel | None:
        """The latest snapshot (None before the first teach of a learner without a model)."""
        return self._snapshot

    @property
    def warming_up(self) -> bool:
        """True while the next teach refits from the kept windows (encoding not yet frozen)."""
        if self._working is None:
            return True  # no model yet: the first teach fits one
        return bool(self._kept) and self.taught_windows < self.config.warmup_windows

    def teach(
        self, samples: Sequence[SubtaskSample], live: Sequence[SubtaskSample] = ()
    ) -> SubtaskModel:
        """Learn labelled windows (sample.subtask = the label, any new name accepted) and return a
        NEW model object (a snapshot the caller may swap in; never mutates a model already returned).

        `live`: live-like windows of the same sub-tasks (the words final at times inside them,
        learn/teaching.py), learned beside the windows and their prefixes.
        """
        samples = list(samples)
        live = list(live)
        if not samples:
            raise InputError("nothing to teach: no windows")
        for s in samples:
            if not isinstance(s.subtask, str) or not s.subtask.strip():
                raise InputError(f"a taught window of trial {s.trial!r} has no label")
        task_before = self.task
        self._grow_task(samples)
        try:
            if self.warming_up:
                self._refit(samples, live)
            else:
                self._extend(samples, live)
        except Exception:
            # a failed teach changes nothing: the working model goes back to the last snapshot
            # (the next teach copies it before changing it)
            self.task = task_before
            if self._snapshot is not None and not self._kept:
                self._working, self._shared = self._snapshot, True
            raise
        if self.task is None:
            self.task = self._working.task if self._working is not None else None
        self.taught_windows += len(samples)
        self.taught_live += len(live)
        if self.taught_windows >= self.config.warmup_windows and self._kept:
            self._freeze()
        working = self._working
        assert working is not None
        working.training = {**working.training, ONLINE_KEY: self.state()}
        self._snapshot = self._snapshot_of(working)
        self._shared = True
        return self._snapshot

    def state(self) -> dict[str, Any]:
        """The teaching state as stored in the model header (a restarted node continues from it)."""
        return {
            "taught_windows": self.taught_windows,
            "warmup_windows": self.config.warmup_windows,
            "prefixes": list(self.config.prefixes),
            "frozen": not self.warming_up,
        }

    # ------------------------------------------------------------------ internals
    def _grow_task(self, samples: Sequence[SubtaskSample]) -> None:
        """A label the task does not name (e.g. a failure class taught later) joins its names,
        after the known ones, so the saved model's task covers every class of its forest."""
        if self.task is None:
            return
        new = [n for n in dict.fromkeys(s.subtask for s in samples) if n not in self.task.subtasks]
        if new:
            self.task = replace(self.task, subtasks=(*self.task.subtasks, *new))

    def _taught_samples(self, samples: Sequence[SubtaskSample]) -> list[SubtaskSample]:
        """The windows and their prefixes, as train_model's augment_prefixes makes them."""
        return with_prefixes(samples, self.config.prefixes)

    def _refit(self, samples: Sequence[SubtaskSample], live: Sequence[SubtaskSample]) -> None:
        """Warm-up: encoding + forest from every window taught so far (= train_model on them,
        their prefixes and the live-like windows)."""
        kept = [*self._kept, *samples]
        kept_live = [*self._kept_live, *live]
        encoding = cast(EncodingName, self.config.encoding)  # checked against ENCODINGS
        self._working = train_model(
            [*self._taught_samples(kept), *kept_live],
            "mondrian",
            encoding,
            random_state=self.random_state,
            n_estimators=self.config.n_estimators,
            cache=self._cache,
            task=self.task or task_of_samples(kept),
            max_nodes=self.config.max_nodes,
            max_points=self.config.max_points,
            taxonomy_profile=self.taxonomy_profile,
            taxonomy_sha256=self.taxonomy_sha256,
        )
        self._kept = kept  # only once the refit succeeded: a failed teach changes nothing
        self._kept_live = kept_live
        self.refits += 1
        self._shared = False

    def _extend(self, samples: Sequence[SubtaskSample], live: Sequence[SubtaskSample]) -> None:
        """After warm-up: the frozen encoding, the forest extended with partial_fit (+ live head)."""
        assert self._working is not None
        if self._shared:
            began = time.perf_counter()
            self._working = _copy_model(self._working)
            self.last_copy_s = time.perf_counter() - began
            self._shared = False
        if self.task is not None:
            self._working.task = self.task  # a copy, never the last snapshot's
        taught = [*self._taught_samples(samples), *live]
        for model in (self._working, self._working.live):
            if model is None:
                continue
            features = model.encoder.transform(taught)
            try:
                model.estimator.partial_fit(features, [s.subtask for s in taught])
            except ValueError as exc:
                raise InputError(f"the forest cannot learn these windows: {exc}") from None
        for s in taught:
            self._working.encoder.cache.forget(s)
            if self._working.live is not None:
                self._working.live.encoder.cache.forget(s)

    def _freeze(self) -> None:
        """End of warm-up: drop the kept windows and their cached features."""
        self._kept = []
        self._kept_live = []
        self._cache = SampleCache()
        if self._working is not None:
            self._working.encoder = with_cache(self._working.encoder, SampleCache())

    def _snapshot_of(self, working: SubtaskModel) -> SubtaskModel:
        """A model sharing the (from now on unchanged) forest, with encoders of its own cache."""
        return replace(
            working,
            encoder=with_cache(working.encoder, SampleCache()),
            training=copy.deepcopy(working.training),
            live=None if working.live is None else self._snapshot_of(working.live),
            window=None,  # a taught model's window mode reads its taught live head
        )


def _require_mondrian(model: SubtaskModel) -> None:
    """Only a Mondrian forest (and a Mondrian live head) can be taught online."""
    for part, name in ((model, "model"), (model.live, "live head")):
        if part is not None and part.classifier != "mondrian":
            raise InputError(
                f"cannot teach a {part.classifier} {name}: online teaching needs the mondrian "
                "classifier (retrain with --classifier mondrian)"
            )


def _copy_model(model: SubtaskModel) -> SubtaskModel:
    """The model with copies of its forests (copy-on-write before partial_fit)."""
    return replace(
        model,
        estimator=copy.deepcopy(model.estimator),
        encoder=with_cache(model.encoder, SampleCache()),
        training=copy.deepcopy(model.training),
        live=None if model.live is None else _copy_model(model.live),
        window=None,  # not taught: window mode reads the taught live head
    )


__all__ = ["OnlineLearner", "TeachConfig", "load_teach_config"]

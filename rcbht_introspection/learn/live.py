"""Live-like training samples: what the classifier node sees while a sub-task runs.

Live, the window of the running sub-task holds only the words already final at time t (primitives
after ~25 ms, compositions after seconds, behaviours mostly at the end), clipped to [start, t].
A model trained on complete sub-tasks only has never seen such windows. `live_windows` streams a
training trial through the segmenter's own code path (live.replay.stream_trial), and at times t
inside each sub-task (every `step_s` and at `fractions` of it) takes the words released by t,
clipped to [start, t], labelled with the true sub-task. Settings: config/live.yaml.
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from rcbht_introspection.config_files import config_path, load_config, to_mapping
from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar.encoding.cache import SampleCache
from rcbht_introspection.grammar.split import SubtaskSample, window_sample
from rcbht_introspection.io.sensor_checks import RepeatedPolicy
from rcbht_introspection.learn import DEFAULT_CLASSIFIER, running_classifier_of
from rcbht_introspection.learn.data import read_any_trial, task_of_trials
from rcbht_introspection.learn.models import RUNNING_PREFIXES, train_model, with_prefixes
from rcbht_introspection.live.replay import StreamedTrial, stream_trial, words_until
from rcbht_introspection.live.segmenter import arm_stream_factory
from rcbht_introspection.taxonomy import StreamProfile
from rcbht_introspection.taxonomy.config import TaxonomyConfig, default_config

if TYPE_CHECKING:
    from rcbht_introspection.learn.models import SubtaskModel

LIVE_CONFIG_FILE = "live.yaml"


@dataclass(frozen=True)
class LiveAugmentConfig:
    """How live-like samples are drawn (config/live.yaml, section live_augment)."""

    enabled: bool = True
    """`rcbht train` adds live samples unless --no-live-augment."""
    step_s: float = 0.25
    """A sample every step_s seconds after the sub-task start."""
    fractions: tuple[float, ...] = (0.25, 0.5, 0.75)
    """And at these fractions of the sub-task (so short sub-tasks get samples too)."""
    max_per_subtask: int = 60
    """At most this many per sub-task (evenly spread), so long sub-tasks do not dominate."""
    window_s: float = 2.0
    """> 0: also the classifier's window mode: words of [t - window_s, t] final by t, labelled
    with the sub-task at t (0: boundary-mode windows only)."""
    taxonomy_profile: str = "reference"
    stream_profile: StreamProfile = "reference"
    """Must match the segmenter node's stream_profile: it decides when words become final."""


def _check(cfg: LiveAugmentConfig) -> None:
    """Ranges beyond the field types (the loader adds file and line to the error)."""
    if cfg.step_s <= 0:
        raise InputError(f"must be > 0, got {cfg.step_s}", field="step_s")
    if cfg.window_s < 0:
        raise InputError(f"must be >= 0, got {cfg.window_s}", field="window_s")
    if cfg.max_per_subtask < 1:
        raise InputError(f"must be >= 1, got {cfg.max_per_subtask}", field="max_per_subtask")
    for i, f in enumerate(cfg.fractions):
        if not 0 < f <= 1:
            raise InputError(f"must be in (0, 1], got {f}", field=f"fractions[{i}]")


def load_live_config(path: Path | str | None = None) -> LiveAugmentConfig:
    """The live_augment section of config/live.yaml (or of `path`)."""
    file = Path(path) if path is not None else config_path(LIVE_CONFIG_FILE)
    return load_config(LiveAugmentConfig, file, section=("live_augment",), check=_check)


def sample_times(start: float, end: float, config: LiveAugmentConfig) -> list[float]:
    """Times t in (start, end] at which a live sample of the sub-task [start, end] is taken."""
    span = end - start
    grid = set(np.round(start + config.step_s * np.arange(1, int(span / config.step_s) + 1), 9))
    grid |= {round(start + f * span, 9) for f in config.fractions}
    times = sorted(t for t in grid if start < t <= end)
    if len(times) > config.max_per_subtask:
        pick = np.linspace(0, len(times) - 1, config.max_per_subtask).round().astype(int)
        times = [times[i] for i in sorted(set(pick))]
    return [float(t) for t in times]


def live_windows(
    streamed: StreamedTrial, config: LiveAugmentConfig
) -> tuple[list[SubtaskSample], list[SubtaskSample]]:
    """(boundary-mode windows [start, t] of each sub-task, window-mode windows [t - window_s, t]
    when window_s > 0), with only the words released by t (empty ones skipped).

    t is moved back to the last segmenter step at or before it: the classifier node's window ends
    at the stream time of the newest evidence it has.
    """
    released = streamed.released()
    step_times = [s.t for s in streamed.steps]
    delivered = streamed.delivered_blocks()
    boundary: list[SubtaskSample] = []
    window: list[SubtaskSample] = []
    for subtask, start, end in streamed.subtask_windows():
        for t in sample_times(start, end, config):
            i = bisect_right(step_times, t) - 1
            now = max(start, step_times[i]) if i >= 0 else start
            words = words_until(released, now, streamed.name)
            wrench = delivered(i)  # the blocks the classifier has at that step
            sample = window_sample(words, start, now, subtask, streamed.name, wrench=wrench)
            if sample_word_count(sample):
                boundary.append(sample)
            if config.window_s > 0:
                lo = max(0.0, now - config.window_s)
                sample = window_sample(words, lo, now, subtask, streamed.name, wrench=wrench)
                if sample_word_count(sample):
                    window.append(sample)
    return boundary, window


def sample_word_count(sample: SubtaskSample) -> int:
    """Number of words in a sample (every arm, level, axis)."""
    return sum(
        len(s) for lv in sample.words.words.values() for ax in lv.values() for s in ax.values()
    )


def stream_factory(config: LiveAugmentConfig, taxonomy: TaxonomyConfig | None = None) -> Any:
    """`arm -> ArmStream` with the stream profile of `config` and the taxonomy profile
    `taxonomy` (None: config.taxonomy_profile)."""

    return arm_stream_factory(
        config.taxonomy_profile, stream_profile=config.stream_profile, taxonomy=taxonomy
    )


def trial_live_windows(
    paths: Iterable[Path],
    config: LiveAugmentConfig,
    factory: Any | None = None,
    repeated: RepeatedPolicy | None = None,
) -> dict[str, tuple[list[SubtaskSample], list[SubtaskSample]]]:
    """Both modes' live windows (live_windows) per trial path (trial folders or bags)."""
    factory = factory or stream_factory(config)
    out = {}
    for path in paths:
        trial = read_any_trial(Path(path), repeated)
        out[str(path)] = live_windows(stream_trial(trial, factory), config)
    return out


def trial_live_samples(
    paths: Iterable[Path],
    config: LiveAugmentConfig,
    factory: Any | None = None,
    repeated: RepeatedPolicy | None = None,
) -> dict[str, list[SubtaskSample]]:
    """Live samples of both modes per trial path (trial folders or bags)."""
    windows = trial_live_windows(paths, config, factory, repeated)
    return {path: boundary + window for path, (boundary, window) in windows.items()}


def training_header(
    config: LiveAugmentConfig | None, n_live: int, taxonomy: TaxonomyConfig | None = None
) -> dict[str, Any]:
    """What the model header records about live augmentation (nodes and users can check it)."""
    if config is None:
        return {"live_augment": None}
    settings = to_mapping(config)
    settings.pop("enabled", None)
    if taxonomy is not None:
        settings["taxonomy_profile"] = taxonomy.profile
    return {"live_augment": {**settings, "n_samples": int(n_live)}}


def train_live_model(
    samples: Sequence[SubtaskSample],
    live: Sequence[SubtaskSample],
    config: LiveAugmentConfig | None,
    taxonomy: TaxonomyConfig | None = None,
    window: Sequence[SubtaskSample] = (),
    **train_kwargs: Any,
) -> SubtaskModel:
    """Model on complete sub-tasks; with `config`, plus a live head on them and the live samples
    and, given window-mode windows (`window`), a head of their own for window mode.

    Final verdicts (finished sub-tasks) keep the complete-sub-task model, so they and the
    steady-state accuracy are unchanged; running windows go to the live head (model.head), or in
    window mode to the window head. A window [t - window_s, t] starts anywhere in a sub-task, a
    boundary window at its start: one head for both reads either worse (docs/results-live.md).
    """

    train_kwargs.setdefault("cache", SampleCache())  # both models encode `samples`
    train_kwargs.setdefault("taxonomy", taxonomy or default_config())  # embedded in the file
    if config is None:
        model = train_model(samples, **train_kwargs)
    else:  # the live head also reads the encoding's running prefixes (learn/models.py)
        prefixes = train_kwargs.pop("running_prefixes", None)
        if prefixes is None:
            prefixes = RUNNING_PREFIXES.get(train_kwargs.get("encoding", "words-wrench"), ())
        model = train_model(samples, running_prefixes=(), **train_kwargs)
        running = {
            **train_kwargs,
            "classifier": running_classifier_of(train_kwargs.get("classifier", DEFAULT_CLASSIFIER)),
        }
        head = [*with_prefixes(samples, prefixes), *live]
        model.live = train_model(head, running_prefixes=(), **running)
        if window:
            model.window = train_model(window, running_prefixes=(), **running)
    model.training = training_header(config, len(live) if config is not None else 0, taxonomy)
    return model


__all__ = [
    "LiveAugmentConfig",
    "live_training",
    "live_windows",
    "load_live_config",
    "sample_times",
    "train_live_model",
    "trial_live_samples",
    "trial_live_windows",
]


def live_training(
    trials: Sequence[Any],
    enabled: bool | None = None,
    config_file: Path | str | None = None,
    taxonomy: TaxonomyConfig | None = None,
    repeated: RepeatedPolicy | None = None,
    **train_kwargs: Any,
) -> tuple[SubtaskModel, int]:
    """(model, number of live samples) for TrialSamples `trials`; `enabled` None = config's.

    `taxonomy`: the profile the trials' words came from, also used for the live windows
    (None: reference, and config/live.yaml's taxonomy_profile for the live windows); `repeated`:
    the repeated-stamp policy the live windows' trials are read with (as the trials were)."""
    config = load_live_config(config_file)
    use = config.enabled if enabled is None else enabled
    samples = [s for t in trials for s in t.samples]
    train_kwargs.setdefault("task", task_of_trials(trials))
    live: list[SubtaskSample] = []
    window: list[SubtaskSample] = []
    if use:
        factory = stream_factory(config, taxonomy)
        paths = [t.path for t in trials]
        for boundary, windows in trial_live_windows(paths, config, factory, repeated).values():
            live.extend(boundary)
            window.extend(windows)
    used = config if use else None
    model = train_live_model(samples, live, used, taxonomy, window, **train_kwargs)
    if used is not None:
        model.training = training_header(used, len(live) + len(window), taxonomy)
    return model, len(live) + len(window)

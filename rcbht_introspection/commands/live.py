"""`rcbht live-eval`: offline live /task_state replay of held-out trials (no ROS), before/after."""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rcbht_introspection.commands.options import (
    add_state_options,
    add_taxonomy_options,
    state_from_args,
    taxonomy_from_args,
)
from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar import ENCODINGS
from rcbht_introspection.learn import (
    CLASSIFIER_HELP,
    CLASSIFIERS,
    DEFAULT_CLASSIFIER,
    WORD_SOURCES,
)
from rcbht_introspection.live import MODES, BeliefMode

if TYPE_CHECKING:
    from rcbht_introspection.io.trial import Trial
    from rcbht_introspection.learn.live import LiveAugmentConfig
    from rcbht_introspection.learn.models import SubtaskModel
    from rcbht_introspection.live.replay import StreamedTrial
    from rcbht_introspection.live.state import TaskStateConfig
    from rcbht_introspection.taxonomy.config import TaxonomyConfig


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the live-eval subcommand."""
    p = subparsers.add_parser(
        "live-eval",
        help="replay held-out trials through the live segmenter + belief tracker offline",
        description="Train on all but the last --held-out trials (without and with live "
        "augmentation, or use --model), replay the held-out trials in turn through the nodes' "
        "own sessions (SegmenterSession, ClassifierSession) exactly as the nodes run them over "
        "successive bags, and report time_accuracy, state "
        "changes per sub-task boundary, the expected calibration error and the final "
        "sub-task verdicts.",
    )
    p.add_argument("inputs", nargs="+", type=Path, metavar="TRIAL_OR_DATASET_DIR")
    p.add_argument("--held-out", type=int, required=True, help="last N trials (sorted) replayed")
    p.add_argument("--model", type=Path, default=None, help="replay this model instead of training")
    p.add_argument(
        "--classifier", choices=CLASSIFIERS, default=DEFAULT_CLASSIFIER, help=CLASSIFIER_HELP
    )
    p.add_argument("--encoding", choices=ENCODINGS, default="words-wrench")
    p.add_argument("--words", choices=WORD_SOURCES, default="auto")
    p.add_argument("--mode", choices=(*MODES, "both"), default="both")
    p.add_argument("--window-s", type=float, default=2.0)
    p.add_argument("--live-config", type=Path, default=None, metavar="YAML")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", type=Path, default=None, metavar="OUT")
    add_taxonomy_options(p, with_model=True)
    add_state_options(p)
    p.set_defaults(func=run_live_eval)


def run_live_eval(args: argparse.Namespace) -> int:
    """Replay the held-out trials through the nodes' code with each model and belief mode;
    print a line per run and write the JSON."""
    from rcbht_introspection.learn.data import find_inputs, read_any_trial
    from rcbht_introspection.learn.live import load_live_config, stream_factory
    from rcbht_introspection.live.replay import node_stream

    paths = find_inputs(args.inputs)
    if not 1 <= args.held_out < len(paths) + (args.model is not None):
        raise InputError(f"--held-out must be 1..{len(paths) - 1}", field="--held-out")
    train_paths, held_paths = paths[: -args.held_out], paths[-args.held_out :]
    config = load_live_config(args.live_config)
    state = state_from_args(args)
    given, taxonomy = _given_model(args)
    factory = stream_factory(config, taxonomy)
    models = given or _live_eval_models(args, train_paths, config, taxonomy, factory)
    held = [read_any_trial(p) for p in held_paths]
    # the held-out trials one after another through the nodes' code, as bags played in turn
    streamed = node_stream(held, factory)
    modes: tuple[BeliefMode, ...] = MODES if args.mode == "both" else (args.mode,)
    result: dict[str, Any] = {
        "train": [p.name for p in train_paths],
        "held_out": [p.name for p in held_paths],
        "taxonomy_profile": taxonomy.profile if taxonomy else config.taxonomy_profile,
        "stream_profile": config.stream_profile,
        "state_rule": dataclasses.asdict(state),
        "results": {},
    }
    result["commanded_phase"] = _commanded_phase_baseline(streamed, held)
    print(
        f"baseline without words (/task_state = the commanded sub-task event): time_accuracy "
        f"{result['commanded_phase']['time_accuracy']}  state changes "
        f"{result['commanded_phase']['state_changes']}"
    )
    for name, model in models.items():
        for mode in modes:
            summary = _replay_scored(args, streamed, held, model, mode, state)
            result["results"][f"{name}/{mode}"] = summary
            _print_replay_line(name, mode, summary)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2))
    return 0


def _given_model(
    args: argparse.Namespace,
) -> tuple[dict[str, SubtaskModel], TaxonomyConfig | None]:
    """The --model (as "model"; none: {}) and the profile that labels the words: the options'
    (refused when it is not the model's), else the one the model embeds."""
    taxonomy = taxonomy_from_args(args)
    if args.model is None:
        return {}, taxonomy
    from rcbht_introspection.learn.model_file import load_model, model_taxonomy

    model = load_model(args.model)
    return {"model": model}, model_taxonomy(model, taxonomy, args.model)


def _live_eval_models(
    args: argparse.Namespace,
    train_paths: list[Path],
    config: LiveAugmentConfig,
    taxonomy: TaxonomyConfig | None,
    factory: Any,
) -> dict[str, SubtaskModel]:
    """The models to compare: one trained without and one with live windows ("before" and
    "after") on the training trials."""
    from rcbht_introspection.grammar.encoding.cache import SampleCache
    from rcbht_introspection.learn.data import load_trials
    from rcbht_introspection.learn.live import train_live_model, trial_live_windows

    models: dict[str, SubtaskModel] = {}
    trials = load_trials(train_paths, args.words, taxonomy)
    samples = [s for t in trials for s in t.samples]
    windows = trial_live_windows(train_paths, config, factory).values()
    live = [s for boundary, _ in windows for s in boundary]
    window = [s for _, in_window in windows for s in in_window]
    kw = dict(
        classifier=args.classifier,
        encoding=args.encoding,
        random_state=args.seed,
        cache=SampleCache(),  # all models encode the same samples
    )
    models["before"] = train_live_model(samples, live, None, taxonomy, **kw)
    models["after"] = train_live_model(samples, live, config, taxonomy, window, **kw)
    n_live = len(live) + len(window)
    print(f"trained on {len(train_paths)} trials: {len(samples)} sub-tasks, +{n_live} live")
    return models


def _commanded_phase_baseline(
    streamed: list[StreamedTrial], held: list[Trial]
) -> dict[str, float | int]:
    """The baseline without words: /task_state is the commanded sub-task event."""
    import numpy as np

    from rcbht_introspection.live.replay import commanded_phase

    phases = [commanded_phase(s, t) for s, t in zip(streamed, held, strict=True)]
    weights = [float(t.time[-1] - t.time[0]) for t in held]
    n_subtasks = sum(len(t.subtask_bounds()) for t in held)
    return {
        "time_accuracy": round(float(np.average([a for a, _ in phases], weights=weights)), 4),
        "state_changes": sum(n for _, n in phases),
        "state_changes_per_boundary": round(sum(n for _, n in phases) / max(1, n_subtasks), 3),
    }


def _replay_scored(
    args: argparse.Namespace,
    streamed: list[StreamedTrial],
    held: list[Trial],
    model: SubtaskModel,
    mode: BeliefMode,
    state: TaskStateConfig,
) -> dict[str, Any]:
    """The replay of `model` in `mode` scored, with its cost per belief and its timelines."""
    from rcbht_introspection.live.replay import replay_beliefs, replay_summary

    began = time.perf_counter()
    reps = replay_beliefs(streamed, model, mode, args.window_s, trials=held, state_config=state)
    elapsed = time.perf_counter() - began
    summary = replay_summary(reps, held)
    # classification cost per belief update (window split + encoding + predict): the
    # classifier node pays this once per word batch
    summary["ms_per_belief"] = round(1000 * elapsed / max(1, sum(r.n_beliefs for r in reps)), 3)
    summary["timelines"] = {r.name: [(round(t, 3), s) for t, s in r.changes] for r in reps}
    return summary


def _print_replay_line(name: str, mode: str, summary: dict[str, Any]) -> None:
    """One line per (model, mode): the scores with and without the state rule, the cost."""
    raw, ece = summary["without_state_rule"], summary["expected_calibration_error"]
    print(
        f"{name:7s} {mode:8s} time_accuracy {summary['time_accuracy']}"
        f"  state changes {summary['state_changes']}"
        f" ({summary['state_changes_per_boundary']} per boundary)"
        f"  without state rule {raw['time_accuracy']} / {raw['state_changes']}"
        f"  subtask_accuracy {summary['subtask_accuracy']}"
        f"  ECE final {ece['final']} running {ece['running']}"
        f"  ms/belief {summary['ms_per_belief']}"
        f"  per trial {summary['per_trial']}"
    )

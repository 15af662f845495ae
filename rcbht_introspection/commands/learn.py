"""`rcbht train` (write a sub-task model) and `rcbht evaluate` (learning-curve or prequential
protocol)."""

from __future__ import annotations

import argparse
import functools
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, get_args

from rcbht_introspection.commands.options import add_taxonomy_options, taxonomy_from_args
from rcbht_introspection.commands.sensor import (
    add_repeated_stamps,
    add_strict,
    repeated_policy,
    report_dropped,
    warn,
)
from rcbht_introspection.errors import InputError
from rcbht_introspection.fleet import BadInputs, add_parallel_options, backend, jobs_from_args
from rcbht_introspection.grammar import ENCODINGS
from rcbht_introspection.learn import (
    CLASSIFIER_HELP,
    CLASSIFIERS,
    DEFAULT_CLASSIFIER,
    WORD_SOURCES,
)
from rcbht_introspection.taxonomy import StreamProfile

PROTOCOLS = ("curve", "prequential")

if TYPE_CHECKING:
    from collections.abc import Callable

    from rcbht_introspection.learn.data import TrialSamples
    from rcbht_introspection.learn.evaluate import Protocol
    from rcbht_introspection.taxonomy.config import TaxonomyConfig


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the train and evaluate subcommands."""
    _register_train(subparsers)
    _register_evaluate(subparsers)


def _register_train(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """`rcbht train`: fit a sub-task classifier on trials and save it."""
    train = subparsers.add_parser("train", help="train a sub-task classifier and save the model")
    train.add_argument("inputs", nargs="+", type=Path, metavar="TRIAL_OR_DATASET_DIR")
    train.add_argument("--out", type=Path, required=True, metavar="MODEL")
    _common(train)
    train.add_argument("--seed", type=int, default=0)
    train.add_argument(
        "--live-augment",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="also train on live-like windows (words final by t); default from "
        "config/live.yaml (docs/live-belief.md)",
    )
    train.add_argument(
        "--live-config",
        type=Path,
        default=None,
        metavar="YAML",
        help="live_augment settings (default config/live.yaml)",
    )
    train.set_defaults(func=run_train)


def _register_evaluate(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """`rcbht evaluate`: the learning-curve or prequential evaluation of a classifier."""
    ev = subparsers.add_parser(
        "evaluate", help="learning-curve or prequential (online teaching) evaluation"
    )
    ev.add_argument("inputs", nargs="+", type=Path, metavar="DATASET_DIR")
    _common(ev)
    ev.set_defaults(classifier=None, encoding=None)  # per protocol: see run_evaluate
    ev.add_argument(
        "--protocol",
        choices=PROTOCOLS,
        default="curve",
        help="curve: learning curve over random splits; prequential: trials taught one by one "
        "through the online learner (Mondrian), scored on the last --held-out trials",
    )
    ev.add_argument(
        "--permutations",
        type=int,
        default=None,
        help="random splits (curve, default 20) or shuffled teaching orders besides the "
        "recording order (prequential, default 4)",
    )
    _add_prequential_options(ev)
    ev.add_argument(
        "--validation-trials",
        type=int,
        default=None,
        help="held-out trials (default: 10 of 46, 8 of 38, 6 of 20, else ~22%%)",
    )
    _add_transfer_option(ev)
    ev.add_argument("--trials", type=int, default=None, help="use only the first N trials")
    ev.add_argument("--seed", type=int, default=0)
    ev.add_argument(
        "--n-estimators",
        type=int,
        default=None,
        help="Mondrian trees (default 100; prequential: the teach config's)",
    )
    ev.add_argument(
        "--no-variant", action="store_true", help="skip the variant without near-empty sub-tasks"
    )
    ev.add_argument(
        "--no-peers",
        action="store_true",
        help="leave out minirocket_baseline (MiniRocket on the raw wrench: the peers extra)",
    )
    _add_live_scoring_options(ev)
    ev.add_argument("--json", type=Path, default=None, metavar="OUT")
    ev.add_argument("--plot", type=Path, default=None, metavar="OUT.png")
    ev.add_argument("--no-progress", action="store_true")
    add_parallel_options(ev, "permutations (curve)")
    ev.set_defaults(func=run_evaluate)


def _add_transfer_option(ev: argparse.ArgumentParser) -> None:
    """`--train TRAIN ...`: a model of other recordings scored on the inputs (run_transfer)."""
    ev.add_argument(
        "--train",
        nargs="+",
        type=Path,
        default=None,
        metavar="TRAIN",
        help="score a model of these recordings (another day, session or robot) on the inputs, "
        "whole and at the prefixes, beside MiniRocket and duration only; --permutations seeds "
        "(default 5)",
    )


def _add_prequential_options(ev: argparse.ArgumentParser) -> None:
    """The options of the prequential protocol: held-out trials and the teach settings."""
    ev.add_argument(
        "--held-out",
        type=int,
        default=None,
        metavar="N",
        help="prequential: score on the last N trials in recording order, never taught "
        "(default: as --validation-trials' default)",
    )
    ev.add_argument(
        "--teach-config",
        type=Path,
        default=None,
        metavar="YAML",
        help="prequential: teach settings (default config/teach.yaml)",
    )
    ev.add_argument(
        "--warmup-windows",
        type=int,
        default=None,
        metavar="N",
        help="prequential: override the teach config's warmup_windows",
    )


def _add_live_scoring_options(ev: argparse.ArgumentParser) -> None:
    """The options that score (and train) on live windows: words final by the window's end."""
    ev.add_argument(
        "--live-augment",
        action="store_true",
        help="score live windows with a live head trained on live windows too (docs/live-belief.md)",
    )
    ev.add_argument(
        "--live-score",
        action="store_true",
        help="score on the validation trials' live windows (live_accuracy)",
    )
    ev.add_argument(
        "--live-config",
        type=Path,
        default=None,
        metavar="YAML",
        help="live_augment settings of the live windows, e.g. stream_profile: live "
        "(default config/live.yaml)",
    )


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--classifier", choices=CLASSIFIERS, default=DEFAULT_CLASSIFIER, help=CLASSIFIER_HELP
    )
    parser.add_argument("--encoding", choices=ENCODINGS, default="words-wrench")
    parser.add_argument(
        "--words",
        choices=WORD_SOURCES,
        default="auto",
        help="golden label files, the batch engine, or golden when present",
    )
    parser.add_argument(
        "--augment-prefixes",
        type=float,
        nargs="*",
        default=[],
        metavar="F",
        help="also train on these fractions of each sub-task (e.g. 0.25 0.5 0.75)",
    )
    parser.add_argument(
        "--max-nodes",
        type=int,
        default=None,
        metavar="N",
        help="Mondrian memory budget: nodes of the whole forest (default unbounded; "
        "docs/learning.md)",
    )
    parser.add_argument(
        "--max-points",
        type=int,
        default=None,
        metavar="N",
        help="Mondrian memory budget: stored training points (default unbounded)",
    )
    add_taxonomy_options(parser)
    parser.add_argument(
        "--stream-profile",
        choices=get_args(StreamProfile),
        default="reference",
        help="engine words as this stream profile emits them (config/stream.yaml; live: every "
        "word final within its finality bound); not reference: golden files are not used",
    )
    add_repeated_stamps(parser)
    add_strict(parser)


def forest_budget(args: argparse.Namespace, n_estimators: int = 100) -> dict[str, int | None]:
    """--max-nodes / --max-points as train_model keywords; a budget for another classifier or
    out of range is an InputError."""
    budget = {"max_nodes": args.max_nodes, "max_points": args.max_points}
    if args.classifier != "mondrian" and any(v is not None for v in budget.values()):
        raise InputError("--max-nodes/--max-points need --classifier mondrian", field="--max-nodes")
    if args.max_nodes is not None and args.max_nodes < n_estimators:
        raise InputError(
            f"--max-nodes must be at least the number of trees ({n_estimators})",
            field="--max-nodes",
        )
    if args.max_points is not None and args.max_points < 0:
        raise InputError("--max-points must be >= 0", field="--max-points")
    return budget


def load_checked(
    args: argparse.Namespace,
    command: str,
    taxonomy: TaxonomyConfig | None,
    bad: BadInputs | None = None,
) -> list[TrialSamples]:
    """The trials of `args.inputs` (engine words labelled by `taxonomy`) read with
    `--repeated-stamps` and `--strict`; their sensor findings printed as warnings (frozen-sensor
    thresholds from config/segmenter.yaml's intake section), and the state times dropped from
    them summarised (commands/sensor.report_dropped). A trial that cannot be read is counted in
    `bad` and left out (fleet.BadInputs; none readable: an error); under --strict it stops the run."""
    from rcbht_introspection.learn.data import find_inputs, load_trial_samples
    from rcbht_introspection.live.intake import load_intake_config
    from rcbht_introspection.taxonomy.stream import load_stream_config

    stream = load_stream_config(args.stream_profile)
    read = functools.partial(
        load_trial_samples, words=args.words, taxonomy=taxonomy, repeated=repeated_policy(args),
        checks=load_intake_config(), stream=stream, strict=args.strict,
    )  # fmt: skip
    jobs = jobs_from_args(args) if hasattr(args, "jobs") else 1
    with backend(getattr(args, "scheduler", None)):
        trials = (bad or BadInputs(command)).collect(
            read, find_inputs(args.inputs), jobs, args.strict
        )
    for trial in trials:
        warn(command, trial.trial, trial.findings)
    report_dropped(command, dropped_counts(trials))
    return trials


def dropped_counts(trials: list[TrialSamples]) -> dict[str, int]:
    """Trial -> state times dropped from it (the JSON's input.dropped_state_times)."""
    return {t.trial: t.dropped_state_times for t in trials}


def input_record(trials: list[TrialSamples]) -> dict[str, Any]:
    """The JSON's `input` record: what the reading dropped from the trials."""
    from rcbht_introspection.io.hiro import dropped_per_trial

    return {"dropped_state_times": dropped_per_trial(dropped_counts(trials))}


def run_train(args: argparse.Namespace) -> int:
    from rcbht_introspection.learn.live import live_training
    from rcbht_introspection.learn.model_file import save_model

    taxonomy = taxonomy_from_args(args)
    budget = forest_budget(args)
    bad = BadInputs("train")
    trials = load_checked(args, "train", taxonomy, bad)
    samples = [s for t in trials for s in t.samples]
    model, n_live = live_training(
        trials, args.live_augment, args.live_config, taxonomy, repeated_policy(args),
        classifier=args.classifier,
        encoding=args.encoding, random_state=args.seed,
        augment_prefixes=tuple(args.augment_prefixes), **budget,
    )  # fmt: skip
    save_model(model, args.out)
    print(
        f"wrote {args.out}: {args.classifier}/{args.encoding}, {len(samples)} samples "
        f"(+{n_live} live) from {len(trials)} trials, {model.encoder.n_features} features, "
        f"classes {model.classes_}, task {list(model.task.subtasks)}, "
        f"taxonomy profile {model.taxonomy_profile!r} ({model.taxonomy_sha256[:12]})"
    )
    return bad.finish(args.strict)


def _clean(value: Any) -> Any:
    """JSON-safe copy (NaN becomes null)."""
    if isinstance(value, float) and math.isnan(value):
        return None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_clean(v) for v in value]
    return value


def run_evaluate(args: argparse.Namespace) -> int:
    from rcbht_introspection.learn.evaluate import evaluate, total_steps

    if args.protocol == "prequential":
        return run_prequential(args)
    if args.permutations is not None and args.permutations < 1:
        raise InputError("--permutations must be at least 1", field="--permutations")
    for option in ("held_out", "teach_config", "warmup_windows"):
        if getattr(args, option) is not None:
            raise InputError(
                f"--{option.replace('_', '-')} belongs to --protocol prequential", field=option
            )
    args.classifier = args.classifier or DEFAULT_CLASSIFIER
    args.encoding = args.encoding or "words-wrench"
    if args.train:
        return run_transfer(args)
    args.permutations = args.permutations or 20
    taxonomy = taxonomy_from_args(args)
    n_estimators = 100 if args.n_estimators is None else args.n_estimators
    budget = forest_budget(args, n_estimators)
    bad = BadInputs("evaluate")
    trials = load_checked(args, "evaluate", taxonomy, bad)
    read = input_record(trials)
    if args.trials is not None:
        trials = trials[: args.trials]
    protocol = _curve_protocol(args, taxonomy, n_estimators, budget)
    jobs = jobs_from_args(args)
    with backend(args.scheduler):
        result = _with_progress(
            args,
            total_steps(trials, protocol),
            f"{args.classifier}/{args.encoding}",
            "step",
            lambda progress: evaluate(trials, protocol, progress=progress, jobs=jobs),
        )
    result["datasets"] = [str(p) for p in args.inputs]
    result["input"] = read
    result["bad_inputs"] = bad.to_dict()
    result["words"] = args.words
    result["stream_profile"] = args.stream_profile
    if args.classifier == "mondrian":
        result["forest_budget"] = budget
    result["taxonomy_profile"] = taxonomy.profile if taxonomy else "reference"
    _report_curve(args, _clean(result))
    return bad.finish(args.strict)


def run_transfer(args: argparse.Namespace) -> int:
    """`rcbht evaluate TEST --train TRAIN`: a model of one set of recordings on another."""
    from rcbht_introspection.learn.evaluate import evaluate_transfer

    taxonomy = taxonomy_from_args(args)
    seeds = args.permutations = args.permutations or 5
    n_estimators = 100 if args.n_estimators is None else args.n_estimators
    budget = forest_budget(args, n_estimators)
    bad = BadInputs("evaluate")
    test = load_checked(args, "evaluate", taxonomy, bad)
    train = load_checked(argparse.Namespace(**{**vars(args), "inputs": args.train}), "evaluate",
                         taxonomy, bad)  # fmt: skip
    protocol = _curve_protocol(args, taxonomy, n_estimators, budget)
    result = evaluate_transfer(train, test, protocol, seeds)
    result.update(
        datasets=[str(p) for p in args.inputs],
        train=[str(p) for p in args.train],
        input=input_record([*train, *test]),
        bad_inputs=bad.to_dict(),
        words=args.words,
        taxonomy_profile=taxonomy.profile if taxonomy else "reference",
    )
    result = _clean(result)
    acc, peer = result["accuracy"], result.get("minirocket_baseline")
    minirocket = f", minirocket {_show(peer['trial_splits']['mean'])}" if peer else ""
    prefixes = ", ".join(f"{k} {_show(v['mean'])}" for k, v in result["prefix_accuracy"].items())
    print(
        f"{args.classifier}/{args.encoding} trained on {len(train)} trials, {len(test)} scored: "
        f"whole {acc['mean']:.4f}{minirocket}, duration only "
        f"{result['duration_baseline']['mean']:.4f}; prefixes {prefixes} ({seeds} seeds)"
    )
    _write_json(args.json, result)
    return bad.finish(args.strict)


def _write_json(path: Path | None, result: dict[str, Any]) -> None:
    """The command's JSON result at `path` (--json), folders made as needed; None: none."""
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(result, indent=2))


def _curve_protocol(
    args: argparse.Namespace,
    taxonomy: TaxonomyConfig | None,
    n_estimators: int,
    budget: dict[str, int | None],
) -> Protocol:
    """The learning-curve protocol of the options; MiniRocket (the peers) unless --no-peers or
    aeon is not importable (then a note on stderr)."""
    from rcbht_introspection.learn.evaluate import Protocol

    return Protocol(
        classifier=args.classifier,
        encoding=args.encoding,
        permutations=args.permutations,
        n_validation=args.validation_trials,
        seed=args.seed,
        n_estimators=n_estimators,
        max_nodes=budget["max_nodes"],
        max_points=budget["max_points"],
        variant=not args.no_variant,
        augment_prefixes=tuple(args.augment_prefixes),
        live_augment=args.live_augment,
        live_score=args.live_score,
        taxonomy=taxonomy,
        repeated=repeated_policy(args),
        live_config=args.live_config,
        peers=not args.no_peers and _peers_importable(),
    )


def _peers_importable() -> bool:
    """True when the peers extra's aeon imports; else a one-line note on stderr."""
    from rcbht_introspection.peers.subtask_baseline import aeon_importable

    if aeon_importable():
        return True
    print(
        "rcbht evaluate: note: aeon is not importable (the peers extra): no minirocket_baseline",
        file=sys.stderr,
    )
    return False


def _report_curve(args: argparse.Namespace, result: dict[str, Any]) -> None:
    """Print the learning curve's summary; write its JSON and plot when asked."""
    ss, base = result["steady_state_accuracy"], result["duration_baseline"]
    peer = result.get("minirocket_baseline")
    minirocket = f"minirocket {_show(peer['mean'])} +- {_show(peer['std'])}, " if peer else ""
    print(
        f"{args.classifier}/{args.encoding}: steady state {ss['mean']:.4f} +- {ss['std']:.4f}, "
        f"duration only {base['mean']:.4f} +- {base['std']:.4f}, {minirocket}"
        f"best of splits {result['best_of_splits']:.4f} ({result['n_trials']} trials, "
        f"{result['n_validation_trials']} held out, {args.permutations} permutations)"
    )
    if "live_accuracy" in result:
        live = result["live_accuracy"]
        print(f"live windows of the validation trials: {live['mean']:.4f} +- {live['std']:.4f}")
    _write_json(args.json, result)
    if args.plot:
        from rcbht_introspection.plots.learning_curve import plot_learning_curve

        plot_learning_curve([result], args.plot, title=", ".join(p.name for p in args.inputs))


def run_prequential(args: argparse.Namespace) -> int:
    """`rcbht evaluate --protocol prequential`: online teaching scored against batch models."""
    from rcbht_introspection.learn.prequential import (
        PERMUTATIONS,
        PrequentialProtocol,
        prequential,
        total_teaches,
    )

    if args.classifier not in (None, "mondrian"):
        raise InputError(
            "the prequential protocol teaches the online Mondrian forest (and retrains the SVM "
            "as its reference); drop --classifier",
            field="--classifier",
        )
    _refuse_curve_options(args)
    permutations = PERMUTATIONS if args.permutations is None else args.permutations
    if permutations < 0:
        raise InputError("--permutations must be at least 0", field="--permutations")
    teach = _teach_settings(args)
    taxonomy = taxonomy_from_args(args)
    bad = BadInputs("evaluate")
    trials = load_checked(args, "evaluate", taxonomy, bad)
    read = input_record(trials)
    if args.trials is not None:
        trials = trials[: args.trials]
    protocol = PrequentialProtocol(
        teach=teach, permutations=permutations, held_out=args.held_out, seed=args.seed
    )
    result = _with_progress(
        args,
        total_teaches(trials, protocol),
        "prequential",
        "teach",
        lambda progress: prequential(trials, protocol, progress=progress),
    )
    result["datasets"] = [str(p) for p in args.inputs]
    result["input"] = read
    result["bad_inputs"] = bad.to_dict()
    result["words"] = args.words
    result["taxonomy_profile"] = taxonomy.profile if taxonomy else "reference"
    result = _clean(result)
    for j, step in enumerate(result["steps"]):
        print(
            f"after {step} trials: online {_show(result['prequential_accuracy'][j])}, "
            f"batch {_show(result['batch_accuracy'][j])}, svm {_show(result['svm_accuracy'][j])}, "
            f"duration only {_show(result['duration_accuracy'][j])}"
        )
    print(
        f"held out: {len(result['held_out_trials'])} trials ({result['held_out_trials'][0]} .. "
        f"{result['held_out_trials'][-1]}), {result['orders']} teaching orders, "
        f"{result['seconds']:.1f} s"
    )
    _write_json(args.json, result)
    return bad.finish(args.strict)


def _teach_settings(args: argparse.Namespace) -> Any:
    """The teach config (--teach-config, else config/teach.yaml) with the options given."""
    from dataclasses import replace

    from rcbht_introspection.learn.online import load_teach_config

    teach = load_teach_config(args.teach_config)
    return replace(
        teach,
        encoding=args.encoding or teach.encoding,
        n_estimators=teach.n_estimators if args.n_estimators is None else args.n_estimators,
        warmup_windows=teach.warmup_windows if args.warmup_windows is None else args.warmup_windows,
        max_nodes=teach.max_nodes if args.max_nodes is None else args.max_nodes,
        max_points=teach.max_points if args.max_points is None else args.max_points,
    )


def _refuse_curve_options(args: argparse.Namespace) -> None:
    """An error for a learning-curve option given with --protocol prequential."""
    refused = {
        "--augment-prefixes (use the teach config's prefixes)": bool(args.augment_prefixes),
        "--live-augment": args.live_augment,
        "--live-score": args.live_score,
        "--validation-trials (use --held-out)": args.validation_trials is not None,
        "--plot": args.plot is not None,
        "--no-variant": args.no_variant,
        "--no-peers": args.no_peers,
        "--jobs/--scheduler": args.jobs != 1 or args.scheduler is not None,
    }
    for option, given in refused.items():
        if given:
            raise InputError(f"{option} does not apply to --protocol prequential")


def _with_progress(
    args: argparse.Namespace,
    total: int,
    desc: str,
    unit: str,
    run: Callable[[Callable[[int], None] | None], dict[str, Any]],
) -> dict[str, Any]:
    """`run(progress)` with its progress on stderr (none with --no-progress): a bar on a
    terminal, plain periodic lines otherwise (commands/progress.py); closed however it ends."""
    if args.no_progress:
        return run(None)
    from rcbht_introspection.commands.progress import progress_bar

    bar = progress_bar(total, desc, unit)

    def tick(n: int) -> None:
        bar.update(n)

    try:
        return run(tick)
    finally:
        bar.close()


def _show(value: float | None) -> str:
    """An accuracy for the console (None: not measured)."""
    return "-" if value is None else f"{value:.4f}"

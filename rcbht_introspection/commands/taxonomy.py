"""`rcbht label`, `rcbht conformance`, `rcbht plot`: the taxonomy on trial folders.

`label` writes the original RCBHT layout (diffable against golden/ files) or JSON lines;
`conformance` checks a dataset against its golden/ outputs; `plot` draws the action grammar.
"""

from __future__ import annotations

import argparse
import functools
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from rcbht_introspection.commands.options import add_taxonomy_options, taxonomy_or_default
from rcbht_introspection.commands.sensor import (
    add_repeated_stamps,
    add_strict,
    repeated_policy,
    report_dropped,
    warn,
)
from rcbht_introspection.errors import InputError
from rcbht_introspection.fleet import (
    BadInputs,
    add_parallel_options,
    add_strict_inputs,
    backend,
    jobs_from_args,
)
from rcbht_introspection.taxonomy.words import Level

if TYPE_CHECKING:
    from rcbht_introspection.io.sensor_checks import RepeatedPolicy
    from rcbht_introspection.io.trial import Trial
    from rcbht_introspection.taxonomy.config import TaxonomyConfig
    from rcbht_introspection.taxonomy.words import TrialWords

ENGINES = ("batch", "stream")
FORMATS = ("rcbht", "jsonl")


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the label, conformance and plot subcommands."""
    p = subparsers.add_parser("label", help="label trial folders with the RCBHT")
    p.add_argument(
        "trials", nargs="+", type=Path, metavar="TRIAL_DIR", help="trial or dataset folders"
    )
    p.add_argument("--out", type=Path, required=True, metavar="DIR")
    p.add_argument("--format", choices=FORMATS, default="rcbht")
    add_taxonomy_options(p)
    p.add_argument("--engine", choices=ENGINES, default="batch")
    add_repeated_stamps(p)
    add_strict_inputs(
        p, "trial folder (a state time after its last sample or out of order makes it one)"
    )
    add_parallel_options(p)
    p.set_defaults(func=run_label)

    p = subparsers.add_parser(
        "conformance", help="compare the engine with a dataset's golden/ files"
    )
    p.add_argument("dataset", type=Path, metavar="DATASET_DIR")
    add_taxonomy_options(p)
    p.add_argument("--engine", choices=ENGINES, default="batch")
    add_repeated_stamps(p)
    add_strict(p)
    p.set_defaults(func=run_conformance)

    p = subparsers.add_parser("plot", help="draw a trial's primitives, MCs and LLBs per axis")
    p.add_argument("trial", type=Path, metavar="TRIAL_DIR")
    p.add_argument("--out", type=Path, required=True, metavar="FILE.png")
    add_taxonomy_options(p)
    p.set_defaults(func=run_plot)


def labeller(engine: str, config: TaxonomyConfig) -> Callable[[Trial], TrialWords]:
    """trial -> TrialWords for the chosen engine and taxonomy profile."""
    if engine == "stream":
        from rcbht_introspection.taxonomy.stream import label_trial_streamed

        return lambda trial: label_trial_streamed(trial, config)
    from rcbht_introspection.taxonomy.batch import label_trial

    return lambda trial: label_trial(trial, config)


# --------------------------------------------------------------------------- label


def checked_reader(
    command: str, args: argparse.Namespace, dropped: dict[str, int] | None = None
) -> Callable[[Path], Trial]:
    """folder -> Trial read with `--repeated-stamps` and `--strict`, its sensor findings printed
    as warnings and the state times dropped from it counted in `dropped` (trial -> count)."""
    from rcbht_introspection.io.hiro import dropped_state_times, read_trial
    from rcbht_introspection.io.sensor_checks import trial_findings
    from rcbht_introspection.live.intake import load_intake_config

    checks = load_intake_config()
    policy = repeated_policy(args)

    def read(folder: Path) -> Trial:
        trial = read_trial(folder, policy, args.strict)
        warn(command, folder.name, trial_findings(trial, checks.frozen_samples, checks.frozen_s))
        if dropped is not None:
            dropped[trial.name] = dropped_state_times(trial)
        return trial

    return read


@dataclass(frozen=True)
class _Labelled:
    """What labelling one trial folder leaves for the summary: its sensor findings and the
    state times dropped from it."""

    folder: Path
    trial: str
    findings: tuple[str, ...]
    dropped: int


def _label_one(
    label: Callable[[Trial], TrialWords],
    read: tuple[RepeatedPolicy | None, bool, int, float],
    fmt: str,
    out: Path,
    folder: Path,
) -> _Labelled:
    """Read one trial folder (`read`: repeated-stamp policy, strict, frozen-sensor thresholds),
    label it and write its words (on any worker)."""
    from rcbht_introspection.io.hiro import dropped_state_times, read_trial
    from rcbht_introspection.io.rcbht_format import write_trial_words
    from rcbht_introspection.io.sensor_checks import trial_findings
    from rcbht_introspection.io.words_jsonl import write_jsonl

    policy, strict, frozen_samples, frozen_s = read
    trial = read_trial(folder, policy, strict)
    words = label(trial)
    if fmt == "rcbht":
        write_trial_words(words, out / folder.name)
    else:
        write_jsonl(words, out / folder.name / "words.jsonl")
    findings = tuple(trial_findings(trial, frozen_samples, frozen_s))
    return _Labelled(folder, trial.name, findings, dropped_state_times(trial))


def run_label(args: argparse.Namespace) -> int:
    from rcbht_introspection.io.hiro import find_trials
    from rcbht_introspection.live.intake import load_intake_config

    label = labeller(args.engine, taxonomy_or_default(args))
    jobs = jobs_from_args(args)
    trials = find_trials(args.trials)
    if not trials:
        raise InputError("no trial folders found", path=args.trials[0])
    checks = load_intake_config()
    read = (repeated_policy(args), args.strict, checks.frozen_samples, checks.frozen_s)
    one = functools.partial(_label_one, label, read, args.format, args.out)
    bad = BadInputs("label")
    with backend(args.scheduler):
        done = bad.collect(one, trials, jobs)
    for d in done:
        warn("label", d.folder.name, d.findings)
    report_dropped("label", {d.trial: d.dropped for d in done})
    print(f"labelled {len(done)} trial(s) into {args.out}")
    return bad.finish(args.strict)


# --------------------------------------------------------------------------- conformance


def run_conformance(args: argparse.Namespace) -> int:
    from rcbht_introspection.io.conformance import CONFORMANCE_LEVELS, compare_arms
    from rcbht_introspection.io.hiro import find_trials

    config = taxonomy_or_default(args)
    label = labeller(args.engine, config)
    dropped: dict[str, int] = {}
    read = checked_reader("conformance", args, dropped)
    trials = [t for t in find_trials([args.dataset]) if (t / "golden").is_dir()]
    if not trials:
        raise InputError("no trial folders with golden/ outputs", path=args.dataset)
    identical = {level: 0 for level in CONFORMANCE_LEVELS}
    total = {level: 0 for level in CONFORMANCE_LEVELS}
    failures: list[str] = []
    for folder in trials:
        words = label(read(folder))
        two_arms = len(words.arms) > 1
        for arm, level, axis, diff in compare_arms(folder, words):
            total[level] += 1
            if diff is None:
                identical[level] += 1
            else:
                where = f"{folder.name} {arm}" if two_arms else folder.name
                failures.append(f"{where} {level.value} {axis}: {diff}")
    report_dropped("conformance", dropped)
    for line in failures:
        print(f"DIFF {line}")
    names = {Level.COMPOSITION: "Composites", Level.BEHAVIOR: "llBehaviors"}
    for level in CONFORMANCE_LEVELS:
        print(f"{names[level]}: {identical[level]}/{total[level]} files identical")
    print(f"{len(trials)} trials, engine {args.engine}, profile {config.profile}")
    return 1 if failures else 0


# --------------------------------------------------------------------------- plot


def run_plot(args: argparse.Namespace) -> int:
    from rcbht_introspection.io.hiro import read_trial
    from rcbht_introspection.plots.action_grammar import plot_trial

    trial = read_trial(args.trial)
    words = labeller("batch", taxonomy_or_default(args))(trial)
    plot_trial(trial, words, args.out)
    print(f"wrote {args.out}")
    return 0

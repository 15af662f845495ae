"""`rcbht audit`: a data set's quality before training (audit/, docs/audit.md).

Prints one block per finding (what, where, how strong, what to do) and the number of labelling
convention changes; `--json` writes the whole report, `--plot` its figure. Findings are not
errors: the exit code is 0 whenever the audit ran; a trial that cannot be read is a finding
('unreadable', in the JSON's bad_inputs too) and, with --strict, exit code 2.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rcbht_introspection.commands.sensor import add_repeated_stamps, repeated_policy
from rcbht_introspection.fleet import (
    STRICT_EXIT,
    add_parallel_options,
    add_strict_inputs,
    backend,
    jobs_from_args,
)


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the audit subcommand."""
    p = subparsers.add_parser(
        "audit",
        help="data-quality report before training: durations, convention changes, sessions, sensor",
        description="Audit trials (dataset folders, trial folders, trial bags; in the order "
        "given, each folder sorted by name): per-trial sub-task durations and their outliers, "
        "changes of the labelling convention, sessions (jumps of the free-motion wrench level), "
        "frozen sensors, dropped stamps, sampling rate and gaps. Each finding says where, how "
        "strong (a permutation-tested statistic) and what to do (docs/audit.md).",
    )
    p.add_argument("inputs", nargs="+", type=Path, metavar="DATA")
    p.add_argument("--json", type=Path, default=None, metavar="OUT.json")
    p.add_argument("--plot", type=Path, default=None, metavar="OUT.png")
    p.add_argument(
        "--alpha",
        type=float,
        default=0.01,
        help="family-wise error level of each test (changepoints after Bonferroni over the "
        "sub-tasks, outliers after Bonferroni over every duration; default 0.01)",
    )
    p.add_argument(
        "--permutations",
        type=int,
        default=9999,
        help="random trial orders of each permutation test (default 9999)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the permutations and classifiers")
    p.add_argument(
        "--no-classifier",
        action="store_true",
        help="skip the classifier check beside each change of the durations",
    )
    add_repeated_stamps(p)
    add_strict_inputs(p, "trial that cannot be read")
    add_parallel_options(p, "trials' reading")
    p.set_defaults(func=run_audit, repeated_stamps="reject")


def run_audit(args: argparse.Namespace) -> int:
    from rcbht_introspection.audit import AuditSettings, audit_paths, report_dict, report_text

    settings = AuditSettings(
        alpha=args.alpha,
        permutations=args.permutations,
        seed=args.seed,
        classifier=not args.no_classifier,
        repeated=repeated_policy(args),
    )
    jobs = jobs_from_args(args)
    with backend(args.scheduler):
        report = audit_paths(args.inputs, settings, jobs)
    for line in report_text(report):
        print(line)
    if args.json is not None or args.plot is not None:
        data = report_dict(report)
        if args.json is not None:
            args.json.parent.mkdir(parents=True, exist_ok=True)
            args.json.write_text(json.dumps(data, indent=1) + "\n")
            print(f"wrote {args.json}")
        if args.plot is not None:
            from rcbht_introspection.plots.audit import plot_audit

            print(f"wrote {plot_audit(data, args.plot)}")
    return STRICT_EXIT if args.strict and report.unreadable else 0

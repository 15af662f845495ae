"""`rcbht sim` (simulate a data set) and `rcbht sim-report` (realism report against real HIRO)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from rcbht_introspection.commands.progress import progress_bar
from rcbht_introspection.errors import InputError
from rcbht_introspection.fleet import add_parallel_options, backend, jobs_from_args

TASK_CHOICES: tuple[str, ...] = ("snap-assembly", "peg-in-hole")
"""sim.tasks.SIM_TASKS, spelled out so that `rcbht --help` does not import MuJoCo."""


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the `sim` and `sim-report` subcommands."""
    _register_sim(subparsers)
    _register_sim_report(subparsers)


def _register_sim(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """`rcbht sim`: simulate a data set of a contact task."""
    p = subparsers.add_parser(
        "sim",
        help="simulate snap-assembly or peg-in-hole trials with MuJoCo",
        description="Simulate trials of a contact task (MuJoCo) into HIRO trial folders or "
        "rosbag2 files.",
    )
    p.add_argument("--trials", type=int, default=12, help="number of trials (default 12)")
    p.add_argument(
        "--task",
        choices=TASK_CHOICES,
        default="snap-assembly",
        help="snap-assembly (HIRO's four sub-tasks, default) or peg-in-hole (reach, search, "
        "insert, release; a noisy 100 Hz sensor)",
    )
    p.add_argument(
        "--scenario",
        choices=("one-arm", "two-arm"),
        default="one-arm",
        help="two-arm: a second arm holds the snap housing (snap-assembly only)",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--sessions",
        type=int,
        default=1,
        help="split the trials into this many recording sessions, each with its own sensor bias "
        "and drift (ranges: the config's sensor.session_*; default 1: none)",
    )
    p.add_argument(
        "--failures",
        action="store_true",
        help="make every second trial a failure, cycling through the failure classes "
        "(misalignment, jamming, missed_snap, deviation_<dirs> per configured deviation class; "
        "snap-assembly only)",
    )
    p.add_argument(
        "--rate",
        type=float,
        default=None,
        metavar="HZ",
        help="sensor output rate; must divide 1 kHz (default: the task's sensor, "
        "200 Hz snap-assembly as HIRO, 100 Hz peg-in-hole)",
    )
    _add_output_options(p)
    add_parallel_options(p)
    p.set_defaults(func=run_sim)


def _add_output_options(p: argparse.ArgumentParser) -> None:
    """Where and how `rcbht sim` writes the set, from which config, with what progress bar."""
    p.add_argument("--out", type=Path, required=True, metavar="DIR")
    p.add_argument("--format", choices=("hiro", "bag"), default="hiro", dest="fmt")
    p.add_argument(
        "--config",
        type=Path,
        default=None,
        help="sim config YAML (default config/sim/snap.yaml, peg-in-hole: config/sim/peg.yaml)",
    )
    p.add_argument(
        "--progress",
        choices=("auto", "on", "off"),
        default="auto",
        help="progress bar (auto: on a terminal for more than 4 trials)",
    )


def _register_sim_report(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """`rcbht sim-report`: a simulated set's realism against the real HIRO set."""
    r = subparsers.add_parser(
        "sim-report",
        help="realism report: simulated vs real LLB label statistics",
        description="Compare LLB label frequencies per sub-task and axis, and trial-to-trial "
        "variability, of a simulated set with the real HIRO set; figures as PNG.",
    )
    r.add_argument("sim_dir", type=Path, metavar="SIM_DIR")
    r.add_argument(
        "--real",
        type=Path,
        default=None,
        metavar="REAL_DIR",
        help="real HIRO set with golden/ folders (default ../shared/data/hiro/REAL_HIRO_ONE_SA_SUCCESS)",
    )
    r.add_argument("--out", type=Path, default=Path("sim_report"), metavar="DIR")
    r.set_defaults(func=run_report)


def run_sim(args: argparse.Namespace) -> int:
    """Simulate and write the data set; print a one-line summary."""
    from rcbht_introspection.sim import write_dataset
    from rcbht_introspection.sim.tasks import load_task_config

    if args.trials < 1:
        raise InputError(f"--trials must be at least 1, got {args.trials}", field="trials")
    config = load_task_config(args.task, args.config)
    progress = args.progress == "on" or (
        args.progress == "auto" and args.trials > 4 and sys.stderr.isatty()
    )
    bar = progress_bar(args.trials, "simulating", "trial") if progress else None
    jobs = jobs_from_args(args)
    start = time.perf_counter()
    with backend(args.scheduler):
        written = write_dataset(
            args.out,
            args.trials,
            scenario=args.scenario,
            seed=args.seed,
            failures=args.failures,
            rate_hz=args.rate,
            fmt=args.fmt,
            progress=bar.update if bar is not None else None,
            config=config,
            task=args.task,
            sessions=args.sessions,
            jobs=jobs,
        )
    elapsed = time.perf_counter() - start
    if bar is not None:
        bar.close()
    kind = args.scenario if args.task == "snap-assembly" else f"{args.task} {args.scenario}"
    print(f"wrote {len(written)} {kind} trials to {args.out} in {elapsed:.1f} s")
    return 0


def run_report(args: argparse.Namespace) -> int:
    """Build the realism report (tables as Markdown + JSON, figures as PNG)."""
    from rcbht_introspection.commands.sim_report import write_report

    summary = write_report(args.sim_dir, args.real, args.out)
    print(summary)
    return 0

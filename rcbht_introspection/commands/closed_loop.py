"""`rcbht closed-loop`: the simulated robot, the verifier and the reference planner in one
process; every policy on the same failing and nominal trials (docs/closed-loop.md)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from rcbht_introspection.commands.progress import progress_bar
from rcbht_introspection.errors import InputError
from rcbht_introspection.fleet import add_parallel_options, backend, jobs_from_args

POLICY_CHOICES = ("none", "retry", "search", "introspect", "oracle")
"""plan.planner.POLICIES, spelled out so that `rcbht --help` imports no engine."""
TASKS = {"snap": "sim/cell.yaml", "peg": "sim/peg.yaml"}
"""Task -> its default simulator config (the snap assembly: the repeated-program cell)."""


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the `closed-loop` subcommand."""
    p = subparsers.add_parser(
        "closed-loop",
        help="run the simulated robot with the verifier and a recovery policy, many trials",
        description="Failing and nominal simulated trials under each policy (none, retry, "
        "search, introspect, oracle): success within k attempts, expected time per success "
        "and unnecessary aborts, as JSON.",
    )
    p.add_argument("--task", choices=tuple(TASKS), default="snap")
    p.add_argument("--trials", type=int, default=20, help="failing trials (default 20)")
    p.add_argument("--nominal", type=int, default=10, help="nominal trials (default 10)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--policy",
        default=",".join(POLICY_CHOICES),
        help=f"comma-separated policies (default all: {','.join(POLICY_CHOICES)})",
    )
    p.add_argument(
        "--classes",
        default=None,
        help="comma-separated failure classes or families (default: all the config's)",
    )
    p.add_argument("--config", type=Path, default=None, help="simulator config (task default)")
    p.add_argument("--recovery", type=Path, default=None, help="recovery table (task default)")
    p.add_argument(
        "--verifier",
        type=Path,
        default=None,
        help="verifier file (rcbht verify-train); default: one trained here on other seeds",
    )
    p.add_argument("--json", type=Path, default=None, metavar="OUT", help="write the results")
    p.add_argument(
        "--save-verifier", type=Path, default=None, metavar="FILE", help="keep the verifier used"
    )
    p.add_argument(
        "--ros",
        type=Path,
        default=None,
        metavar="DIR",
        help="also run the trials through the nodes over DDS (sim, segmenter, verifier, planner "
        "and, with --model, classifier), logs in DIR; the JSON compares them trial for trial",
    )
    p.add_argument("--rate-factor", type=float, default=4.0, help="--ros: sim speed (default 4)")
    p.add_argument("--model", type=Path, default=None, help="--ros: classifier_node's model file")
    add_parallel_options(p)
    p.set_defaults(func=cmd_closed_loop)


def _policies(text: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    bad = [n for n in names if n not in POLICY_CHOICES]
    if bad or not names:
        raise InputError(
            f"unknown policy {', '.join(map(repr, bad)) or repr(text)} (known: {', '.join(POLICY_CHOICES)})",
            field="policy",
        )
    return names


def _classes(all_classes: tuple[str, ...], text: str | None) -> list[str]:
    if text is None:
        return list(all_classes)
    asked = [c.strip() for c in text.split(",") if c.strip()]
    chosen = [c for c in all_classes if any(c == a or c.startswith(f"{a}_") for a in asked)]
    if not chosen:
        raise InputError(
            f"no failure class matches {text!r} (known: {', '.join(all_classes)})",
            field="classes",
        )
    return chosen


def cmd_closed_loop(args: argparse.Namespace) -> int:
    """Draw the worlds, train or load the verifier, run the policies, write the JSON."""
    from rcbht_introspection.closed_loop.experiment import draw_worlds
    from rcbht_introspection.config_files import config_path
    from rcbht_introspection.plan.recovery import load_recovery_config
    from rcbht_introspection.sim import load_sim_config
    from rcbht_introspection.sim.peg_config import load_peg_config
    from rcbht_introspection.sim.tasks import task_failure_classes

    if args.trials < 0 or args.nominal < 0 or args.trials + args.nominal == 0:
        raise InputError("need at least one trial (--trials, --nominal)", field="trials")
    if args.ros is not None and args.task != "snap":
        raise InputError("sim_node runs the snap task only", field="ros")
    policies: list[Any] = _policies(args.policy)
    load = load_peg_config if args.task == "peg" else load_sim_config
    config = load(args.config or config_path(TASKS[args.task]))
    recovery = load_recovery_config(args.task, args.recovery)
    classes = _classes(task_failure_classes(config), args.classes)
    jobs = jobs_from_args(args)
    with backend(args.scheduler):
        verifier = _verifier(args, config, classes, policies, recovery.abort_rate, jobs)
        worlds = draw_worlds(config, classes, args.trials, args.nominal, args.seed, jobs)
        result = _run(args, config, worlds, policies, recovery, verifier, jobs)
    result["classes"] = classes
    if args.ros is not None:
        result["ros"] = _over_ros(args, worlds, policies, result, verifier)
    text = json.dumps(result, indent=2)
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(text + "\n")
    print(_table(result), file=sys.stderr if args.json is None else sys.stdout)
    if args.json is None:
        print(text)
    return 0


def _verifier(
    args: argparse.Namespace,
    config: Any,
    classes: list[str],
    policies: list[str],
    abort_rate: float,
    jobs: int,
) -> Any:
    """The verifier file, else one trained here at the planner's abort rate; None when no
    policy reads verdicts."""
    import dataclasses

    from rcbht_introspection.closed_loop.experiment import train_default_verifier
    from rcbht_introspection.verify.config import load_verify_config
    from rcbht_introspection.verify.model_file import load_verifier

    if not {"introspect", "oracle"} & set(policies) and args.ros is None:
        return None
    from rcbht_introspection.verify.model_file import save_verifier

    if args.verifier is not None:
        try:
            return load_verifier(args.verifier)
        except (OSError, ValueError) as exc:
            raise InputError(f"unusable verifier: {exc}", path=args.verifier) from None
    print("training a verifier on other seeds of the same config ...", file=sys.stderr)
    verify_config = dataclasses.replace(load_verify_config(), false_alarm_rate=abort_rate)
    model = train_default_verifier(config, classes, verify_config, args.seed, jobs=jobs)
    if args.save_verifier is not None:
        save_verifier(model, args.save_verifier)
    return model


def _run(
    args: argparse.Namespace,
    config: Any,
    worlds: Any,
    policies: list[Any],
    recovery: Any,
    verifier: Any,
    jobs: int,
) -> dict[str, Any]:
    from rcbht_introspection.closed_loop.experiment import policy_summary, run_policies

    total = len(policies) * (len(worlds.failing) + len(worlds.nominal))
    bar = progress_bar(total, "closed loop", "trial")
    try:
        records = run_policies(config, worlds, policies, recovery, verifier, jobs, bar.update)
    finally:
        bar.close()
    return {
        "task": args.task,
        "seed": args.seed,
        "max_attempts": recovery.max_attempts,
        "failing_trials": len(worlds.failing),
        "nominal_trials": len(worlds.nominal),
        "not_failing_draws": worlds.not_failing,
        "verifier": None if verifier is None else verifier.trained_on,
        "policies": {p: policy_summary(records[p], recovery.max_attempts) for p in policies},
    }


def _table(result: dict[str, Any]) -> str:
    """One line per policy: success within 1..k attempts, time per success, nominal aborts."""
    lines = [
        f"{result['failing_trials']} failing and {result['nominal_trials']} nominal trials "
        f"(draws that seated uncorrected: {result['not_failing_draws'] or 'none'})"
    ]
    for name, s in result["policies"].items():
        within = " / ".join(str(v) for v in s["success_within_attempts"].values())
        lines.append(
            f"{name:>10}: success within 1..{result['max_attempts']} attempts {within}; "
            f"time per success {s['time_per_success_s']} s; "
            f"aborts per nominal trial {s['unnecessary_aborts_per_nominal_trial']}; "
            f"nominal mean time {s['nominal_mean_time_s']} s"
        )
    return "\n".join(lines)


def _over_ros(
    args: argparse.Namespace,
    worlds: Any,
    policies: list[str],
    result: dict[str, Any],
    verifier: Any,
) -> dict[str, Any]:
    """Each policy's trials through the nodes; per trial, whether its decisions match the
    offline run's (kinds, classes, corrections; abort times within a tolerance)."""
    from rcbht_introspection.closed_loop.experiment import compare_decisions, stop_success
    from rcbht_introspection.replay.closed_loop import RosLoopOptions, run_over_ros, sample_counts
    from rcbht_introspection.verify.model_file import save_verifier

    verifier_file = args.verifier or save_verifier(verifier, args.ros / "verifier.npz")
    items = [(w.seed, w.failure) for w in (*worlds.failing, *worlds.nominal)]
    out: dict[str, Any] = {}
    for policy in policies:
        options = RosLoopOptions(
            args.ros / policy, policy, str(verifier_file), str(args.config or ""),
            str(args.recovery or ""), str(args.model or ""), args.rate_factor,
        )  # fmt: skip
        runs, codes = run_over_ros(items, options)
        offline = result["policies"][policy]["trials"]
        out[policy] = {
            "exit_codes": codes,
            "samples": sample_counts(options.work),
            "success_over_ros": stop_success([r.decisions for r in runs if r.failure]),
            "success_offline": stop_success(
                [t["decisions"] for t in offline if t["class"] != "nominal"]
            ),
            "same_decisions": [
                compare_decisions(t["decisions"], r.decisions)
                for t, r in zip(offline, runs, strict=True)
            ],
            "trials": [
                {"seed": r.seed, "class": r.failure or "nominal", "decisions": r.decisions}
                for r in runs
            ],
        }
    return out

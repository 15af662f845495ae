"""`rcbht bag from-hiro|import|replay|record|info` and `rcbht replay-eval`: bags and the live nodes."""

from __future__ import annotations

import argparse
import functools
import json
import time
from pathlib import Path
from typing import TYPE_CHECKING, get_args

from rcbht_introspection.commands.options import add_state_options, state_from_args
from rcbht_introspection.configure.spin import DEFAULT_SPIN, Spin
from rcbht_introspection.errors import InputError
from rcbht_introspection.fleet import (
    BadInputs,
    Failed,
    add_parallel_options,
    add_strict_inputs,
    attempt,
    backend,
    jobs_from_args,
    parallel_map,
)
from rcbht_introspection.live import BeliefMode
from rcbht_introspection.taxonomy import StreamProfile

if TYPE_CHECKING:
    from rcbht_introspection.io.bag_import import PlannedImport


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the `bag` and `replay-eval` subcommands."""
    bag = subparsers.add_parser("bag", help="convert, replay and record rosbag2 trial bags")
    sub = bag.add_subparsers(dest="bag_command", required=True, metavar="BAG_COMMAND")
    _register_from_hiro(sub)
    _register_replay(sub)
    _register_record(sub)
    _register_info(sub)
    _register_import(sub)
    _register_replay_eval(subparsers)


def _register_from_hiro(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """`rcbht bag from-hiro`: HIRO trial folders to trial bags."""
    p = sub.add_parser("from-hiro", help="HIRO trial folder(s) -> bag(s) (/wrench, /task_phase)")
    p.add_argument("trial_dir", type=Path, help="a trial folder or a dataset folder of trials")
    p.add_argument(
        "out", type=Path, help="bag path (x.mcap / x.db3), or a folder for a dataset (one bag each)"
    )
    p.add_argument(
        "--format", choices=("mcap", "db3"), default="mcap", help="storage for a dataset"
    )
    p.set_defaults(func=cmd_from_hiro)


def _register_replay(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """`rcbht bag replay`: publish a bag with its recorded timing."""
    p = sub.add_parser("replay", help="publish a bag with its recorded timing (ros2 bag play)")
    p.add_argument("bag", type=Path)
    p.add_argument("--rate", type=float, default=1.0, help="playback speed factor (default 1)")
    p.add_argument(
        "--wait", type=float, default=5.0, help="seconds to wait for subscribers (0: do not)"
    )
    p.set_defaults(func=cmd_replay)


def _register_record(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """`rcbht bag record`: record topics to a bag, raw."""
    p = sub.add_parser("record", help="record topics to a bag, raw (ros2 bag record)")
    p.add_argument("topics", nargs="+")
    p.add_argument("--out", type=Path, required=True, help="bag path (x.mcap / x.db3)")
    p.add_argument("--duration", type=float, default=0.0, help="seconds (0: until Ctrl-C)")
    p.add_argument("--wait", type=float, default=10.0, help="seconds to wait for the topics")
    p.set_defaults(func=cmd_record)


def _register_info(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """`rcbht bag info`: what a bag holds."""
    p = sub.add_parser("info", help="topics, types and message counts of a bag")
    p.add_argument("bag", type=Path)
    p.set_defaults(func=cmd_info)


def _register_replay_eval(
    subparsers: argparse._SubParsersAction[argparse.ArgumentParser],
) -> None:
    """`rcbht replay-eval`: bags through the live nodes over real DDS, scored."""
    p = subparsers.add_parser(
        "replay-eval",
        help="replay bags through segmenter_node and classifier_node (and verifier_node) over real DDS and score them",
    )
    p.add_argument("bags", nargs="+", type=Path, help="trial bags (or folders of bags)")
    p.add_argument(
        "--model",
        type=Path,
        default=None,
        help="model file from `rcbht train` (not with --teach-first)",
    )
    p.add_argument("--rate", type=float, default=1.0, help="playback speed factor")
    p.add_argument("--json", type=Path, default=None, help="write the scores here")
    p.add_argument("--mode", choices=get_args(BeliefMode), default="boundary")
    _add_segmenter_options(p)
    add_state_options(p)
    p.add_argument("--timeline", action="store_true", help="print the /task_state timeline")
    _add_teach_first_options(p)
    p.add_argument(
        "--verifier",
        type=Path,
        default=None,
        metavar="FILE",
        help="verifier file (`rcbht verify-train`): run verifier_node too and report its alarms, "
        "detection delays against the labelled onsets and false alarms on nominal runs",
    )
    p.set_defaults(func=cmd_replay_eval)


def _add_segmenter_options(p: argparse.ArgumentParser) -> None:
    """replay-eval's taxonomy and stream profile of segmenter_node."""
    p.add_argument(
        "--profile",
        default="",
        help="taxonomy profile of the segmenter: of config/rcbht.yaml, or of --taxonomy-config "
        "(default: its only profile); it must be the model's (default: the profile the model "
        "file carries, else reference)",
    )
    p.add_argument(
        "--taxonomy-config",
        default="",
        metavar="FILE",
        help="YAML file of taxonomy profiles for the segmenter, e.g. written by `rcbht calibrate` "
        "(default: the model's own profile)",
    )
    p.add_argument(
        "--stream-profile",
        choices=get_args(StreamProfile),
        default="reference",
        help="stream profile of the segmenter (causal: moment-axis words without waiting; "
        "live: every word final within finality_bound_s)",
    )
    p.add_argument(
        "--spin",
        choices=get_args(Spin),
        default=DEFAULT_SPIN,
        help="the nodes' spin: events (rclpy's EventsExecutor) or executor (its "
        "SingleThreadedExecutor)",
    )


def _add_teach_first_options(p: argparse.ArgumentParser) -> None:
    """replay-eval's teaching run: a classifier without a model, taught the first bags."""
    p.add_argument(
        "--teach-first",
        type=int,
        default=0,
        metavar="K",
        help="start the classifier without a model, teach it the first K bags' sub-tasks through "
        "its ~/teach service (one bag at a time, in order), then score the others",
    )
    p.add_argument(
        "--teach-restart",
        action="store_true",
        help="with --teach-first: restart the classifier from its saved model and replay the "
        "scored bags again (the verdicts must not change)",
    )
    p.add_argument(
        "--teach-beside",
        action="store_true",
        help="with --teach-first: learn each taught bag while the next one plays (teaching "
        "beside the live path; those bags' latency is reported as teach.latency_beside_ms)",
    )
    p.add_argument(
        "--teach-file",
        type=Path,
        default=None,
        help="with --teach-first: keep the taught model here (must not exist yet)",
    )


IMPORT_HELP = """\
Import another robot's ROS 1 bags (.bag) or rosbag2 bags (.mcap, .db3, bag directory) as trial
bags (/wrench or /<arm>/wrench, /task_phase, /rcbht/trial_info), one OUT/<name>.mcap per bag.
Message definitions come from the bag itself, so custom types need no robot packages.

SPEC is a topic (/ft_sensor) or a field path into its messages (/tag_multimodal.wrench_stamped):
a WrenchStamped or Wrench for --wrench, a string or an integer for --phase.

Stamps: a stamp equal to the previous kept one is dropped (the first is kept), one before it is
dropped, a zero header stamp is dropped; samples before the first phase and after the end phase
are cut. Each count is printed and stored in the bag's trial info ("import"). Phase events: an
event naming the running phase continues it, a phase without samples is dropped, events after
the end phase are not used.

Outside the task: a phase named '-' (--phase-map 0=-) or listed in --out-of-task, e.g. the robot
idle before and after the task, is neither a sub-task nor the end phase. Such events before the
first task phase are skipped; the first one after a task phase ends the trial there. Details:
docs/bags.md, "Importing bags from another robot".

Example (the Baxter pick-and-place bags: tag 0 idle, then 1, 2, 5, 3, 4):
  rcbht bag import session_a/*.bag other_sessions/*.bag --out baxter/ \
      --wrench /tag_multimodal.wrench_stamped --phase /tag_multimodal.tag \
      --phase-map 0=-,1=approach,2=grasp,5=lift,3=transport,4=place
"""


def _register_import(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """`rcbht bag import`: another robot's bags to trial bags."""
    p = sub.add_parser(
        "import",
        help="another robot's ROS 1 / rosbag2 bags -> trial bags",
        description=IMPORT_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("bags", nargs="+", type=Path, help="ROS 1 or rosbag2 bags")
    p.add_argument("--out", type=Path, required=True, help="folder for the trial bags")
    p.add_argument("--format", choices=("mcap", "db3"), default="mcap", help="output storage")
    p.add_argument(
        "--wrench",
        action="append",
        default=[],
        metavar="[ARM=]SPEC",
        help="wrench of an arm (repeat for several arms; no ARM: R); "
        "default: the bag's one WrenchStamped/Wrench topic as arm R",
    )
    _add_phase_options(p)
    p.add_argument(
        "--stamps",
        choices=("auto", "header", "receive"),  # io.bag_import.STAMP_SOURCES (imported lazily)
        default="auto",
        help="sample times: header stamps, receive (log) times, or auto: header when there is one",
    )
    p.add_argument(
        "--rate",
        type=float,
        default=None,
        metavar="HZ",
        help="resample to HZ (linear; default off)",
    )
    p.add_argument(
        "--task", type=Path, default=None, metavar="TASK_YAML", help="the task of the trials"
    )
    p.add_argument(
        "--json",
        type=Path,
        default=None,
        metavar="OUT",
        help="write each import's report and the bad bags (bad_inputs) as JSON",
    )
    add_strict_inputs(p, "bag")
    add_parallel_options(p, "bags")
    p.set_defaults(func=cmd_import)


def _add_phase_options(p: argparse.ArgumentParser) -> None:
    """`bag import`'s phase source and how its values are named."""
    phase = p.add_mutually_exclusive_group(required=True)
    phase.add_argument(
        "--phase", metavar="SPEC", help="string phase names, or integers with --phase-map"
    )
    phase.add_argument(
        "--phase-csv",
        type=Path,
        metavar="CSV",
        help="file with header 'time,phase' (seconds from the bag's first wrench sample) or "
        "'stamp,phase' (absolute seconds, the clock of the stamps); a folder: <bag name>.csv each",
    )
    p.add_argument(
        "--phase-map",
        metavar="V=NAME,...",
        help="names of integer phase values, e.g. 0=-,1=reach,2=grasp,3= (empty name: the end; "
        "'-': outside the task)",
    )
    p.add_argument(
        "--out-of-task",
        default="",
        metavar="NAME,...",
        help="phase names outside the task (string phases or a phase CSV), e.g. idle; "
        "'-' always is",
    )
    p.add_argument(
        "--end-phase",
        default=None,
        metavar="NAME",
        help="phase that ends the trial (default: the --task end phases, else done); "
        "without one the trial ends at its last sample",
    )


def _bags(paths: list[Path]) -> list[Path]:
    from rcbht_introspection.io.bags import BAG_SUFFIXES, is_bag

    out: list[Path] = []
    for p in paths:
        if is_bag(p):
            out.append(p)
        elif p.is_dir():
            found = sorted(c for c in p.iterdir() if is_bag(c))
            if not found:
                raise InputError(f"no bags ({', '.join(BAG_SUFFIXES)}) in folder", p)
            out.extend(found)
        else:
            raise InputError("not a bag or a folder of bags", p)
    return out


def cmd_from_hiro(args: argparse.Namespace) -> int:
    from rcbht_introspection.io.bags import BAG_SUFFIXES, write_trial_bag
    from rcbht_introspection.io.hiro import find_trials, read_trial

    trials = find_trials([args.trial_dir])
    if not trials:
        raise InputError("no trial folders", args.trial_dir)
    single = len(trials) == 1 and args.out.suffix in BAG_SUFFIXES
    for folder in trials:
        out = args.out if single else args.out / f"{folder.name}.{args.format}"
        write_trial_bag(read_trial(folder), out)
        print(out)
    return 0


def cmd_import(args: argparse.Namespace) -> int:
    from rcbht_introspection.io.bag_import import ImportOptions, parse_wrench_specs, plan_imports
    from rcbht_introspection.io.bags import END_PHASE
    from rcbht_introspection.io.phase_events import parse_phase_map
    from rcbht_introspection.live.intake import load_intake_config
    from rcbht_introspection.task import load_task_file

    checks = load_intake_config()
    task = load_task_file(args.task) if args.task is not None else None
    if args.end_phase is not None:
        end_phases: tuple[str, ...] = (args.end_phase,)
    else:
        end_phases = task.end_phases if task is not None else (END_PHASE,)
    options = ImportOptions(
        wrench=parse_wrench_specs(args.wrench),
        phase=args.phase or "",
        phase_map=parse_phase_map(args.phase_map) if args.phase_map is not None else None,
        phase_csv=args.phase_csv,
        out_of_task=tuple(n.strip() for n in args.out_of_task.split(",") if n.strip()),
        end_phases=end_phases,
        stamps=args.stamps,
        rate_hz=args.rate,
        task=task,
        frozen=(checks.frozen_samples, checks.frozen_s),  # the thresholds train warns with
    )
    return _run_imports(args, plan_imports(args.bags, args.out, options, f".{args.format}"))


def _run_imports(args: argparse.Namespace, planned: list[PlannedImport]) -> int:
    """Import every planned bag (on --jobs workers); a bag that cannot be imported is named and
    counted and the others are written (fleet.BadInputs: the exit code, --json's bad_inputs)."""
    from rcbht_introspection.commands.sensor import warn
    from rcbht_introspection.io.bag_import import PlannedImport

    jobs = jobs_from_args(args)
    with backend(args.scheduler):
        outcomes = parallel_map(functools.partial(attempt, PlannedImport.run), planned, jobs)
    bad = BadInputs("bag import")
    reports: list[dict[str, object]] = []
    for plan, outcome in zip(planned, outcomes, strict=True):
        if not isinstance(outcome, Failed):
            print(f"{plan.bag} -> {plan.out}: {outcome.summary()}", flush=True)
            warn("bag import", plan.out.name, outcome.findings)
            reports.append({"bag": str(plan.bag), "out": str(plan.out), **outcome.to_dict()})
    bad.keep(outcomes)
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        record = {"imported": reports, "bad_inputs": bad.to_dict()}
        args.json.write_text(json.dumps(record, indent=1) + "\n")
    bad.check_some()
    print(f"imported {len(reports)} of {len(planned)} bag(s) into {args.out}")
    return bad.finish(args.strict)


def cmd_info(args: argparse.Namespace) -> int:
    from rcbht_introspection.io.bags import bag_messages

    counts: dict[tuple[str, str], int] = {}
    first = last = None
    for m in bag_messages(args.bag):
        counts[(m.topic, m.msgtype)] = counts.get((m.topic, m.msgtype), 0) + 1
        first = m.t_ns if first is None else first
        last = m.t_ns
    print(
        f"{args.bag}: {sum(counts.values())} messages, {((last or 0) - (first or 0)) / 1e9:.3f} s"
    )
    for (topic, msgtype), n in sorted(counts.items()):
        print(f"  {topic}  {msgtype}  {n}")
    return 0


def cmd_replay(args: argparse.Namespace) -> int:
    from rcbht_introspection.io.bags import TRIAL_INFO_TOPIC, bag_messages
    from rcbht_introspection.lifetime import StopSignal
    from rcbht_introspection.rostools.player import BagPlayer
    from rcbht_introspection.rostools.session import RosSession

    stop = StopSignal.install()  # Ctrl-C ends the playback between two messages
    messages = list(bag_messages(args.bag))
    with RosSession("rcbht_bag_player") as ros:
        player = BagPlayer(ros.node)
        player.prepare(messages)
        live = [t for t in player.publishers if t != TRIAL_INFO_TOPIC]  # metadata: no one waits
        if args.wait > 0 and not player.wait_for_subscribers(live, args.wait, stop):
            print("note: not every topic has a subscriber; playing anyway")
        t0 = time.perf_counter()
        n = player.play(messages, rate=args.rate, stop=stop)
        print(f"published {n} messages in {time.perf_counter() - t0:.2f} s (rate {args.rate}x)")
        if not stop.requested:  # reliable subscribers got everything before the player goes
            player.wait_for_acks(4.0, stop)
    stop.exiting()
    return 0


def cmd_record(args: argparse.Namespace) -> int:
    from rcbht_introspection.lifetime import StopSignal
    from rcbht_introspection.rostools.player import RawRecorder
    from rcbht_introspection.rostools.session import RosSession

    # SIGINT/SIGTERM end the recording where this loop checks, never inside a bag write
    stop = StopSignal.install()
    with RosSession("rcbht_bag_recorder") as ros:
        recorder = RawRecorder(ros.node, args.out)
        types = recorder.resolve(args.topics, args.wait, stop)
        missing = [t for t in args.topics if ("/" + t.lstrip("/")) not in types]
        if missing and not stop.requested:
            recorder.bag.abort()
            raise InputError(f"topic(s) not seen within {args.wait} s: {', '.join(missing)}")
        try:
            for topic, msgtype in sorted(types.items()):
                recorder.subscribe(topic, msgtype)
            if not stop.requested:
                print(
                    f"recording {', '.join(sorted(types))} to {args.out} (Ctrl-C to stop)",
                    flush=True,
                )
            deadline = time.monotonic() + args.duration if args.duration > 0 else None
            while not stop.wait(0.05) and (deadline is None or time.monotonic() < deadline):
                pass
            ros.settle()  # what was delivered before the stop still goes into the bag
        finally:
            recorder.close()  # the bag is readable whatever happened
    print(json.dumps(recorder.counts))
    stop.exiting()
    return 0


def cmd_replay_eval(args: argparse.Namespace) -> int:
    from rcbht_introspection.replay.harness import ReplayEvalOptions, replay_eval
    from rcbht_introspection.replay.scoring import summary

    options = ReplayEvalOptions(
        rate=args.rate,
        mode=args.mode,
        profile=args.profile,
        taxonomy_config_file=str(Path(args.taxonomy_config).resolve())
        if args.taxonomy_config
        else "",
        stream_profile=args.stream_profile,
        spin=args.spin,
        state=state_from_args(args),
        teach_first=args.teach_first,
        teach_restart=args.teach_restart,
        teach_beside=args.teach_beside,
        teach_file=args.teach_file.resolve() if args.teach_file else None,
        verifier_file=args.verifier.resolve() if args.verifier else None,
    )
    if args.model is None and not args.teach_first and args.verifier is None:
        raise InputError(
            "give --model (or --teach-first K to teach the classifier, or --verifier FILE)"
        )
    if (args.teach_restart or args.teach_file or args.teach_beside) and not args.teach_first:
        raise InputError("--teach-restart, --teach-beside and --teach-file need --teach-first")
    result = replay_eval(_bags(args.bags), args.model, options)
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2))
    print(summary(result, timeline=args.timeline))
    if "verifier" in result:
        from rcbht_introspection.replay.verify_scoring import verifier_summary

        print(verifier_summary(result["verifier"]))
    return 0

"""`rcbht bag from-hiro|replay|record|info` and `rcbht replay-eval`: bags and the live nodes."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import get_args

from rcbht_introspection.errors import InputError
from rcbht_introspection.live import BeliefMode
from rcbht_introspection.taxonomy import StreamProfile


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `bag` and `replay-eval` subcommands."""
    bag = subparsers.add_parser("bag", help="convert, replay and record rosbag2 trial bags")
    sub = bag.add_subparsers(dest="bag_command", required=True, metavar="BAG_COMMAND")

    p = sub.add_parser("from-hiro", help="HIRO trial folder(s) -> bag(s) (/wrench, /task_phase)")
    p.add_argument("trial_dir", type=Path, help="a trial folder or a dataset folder of trials")
    p.add_argument(
        "out", type=Path, help="bag path (x.mcap / x.db3), or a folder for a dataset (one bag each)"
    )
    p.add_argument(
        "--format", choices=("mcap", "db3"), default="mcap", help="storage for a dataset"
    )
    p.set_defaults(func=cmd_from_hiro)

    p = sub.add_parser("replay", help="publish a bag with its recorded timing (ros2 bag play)")
    p.add_argument("bag", type=Path)
    p.add_argument("--rate", type=float, default=1.0, help="playback speed factor (default 1)")
    p.add_argument(
        "--wait", type=float, default=5.0, help="seconds to wait for subscribers (0: do not)"
    )
    p.set_defaults(func=cmd_replay)

    p = sub.add_parser("record", help="record topics to a bag, raw (ros2 bag record)")
    p.add_argument("topics", nargs="+")
    p.add_argument("--out", type=Path, required=True, help="bag path (x.mcap / x.db3)")
    p.add_argument("--duration", type=float, default=0.0, help="seconds (0: until Ctrl-C)")
    p.add_argument("--wait", type=float, default=10.0, help="seconds to wait for the topics")
    p.set_defaults(func=cmd_record)

    p = sub.add_parser("info", help="topics, types and message counts of a bag")
    p.add_argument("bag", type=Path)
    p.set_defaults(func=cmd_info)

    p = subparsers.add_parser(
        "replay-eval",
        help="replay bags through segmenter_node and classifier_node (real DDS) and score them",
    )
    p.add_argument("bags", nargs="+", type=Path, help="trial bags (or folders of bags)")
    p.add_argument("--model", type=Path, required=True, help="model file from `rcbht train`")
    p.add_argument("--rate", type=float, default=1.0, help="playback speed factor")
    p.add_argument("--json", type=Path, default=None, help="write the scores here")
    p.add_argument("--mode", choices=get_args(BeliefMode), default="boundary")
    p.add_argument("--profile", default="reference", help="taxonomy profile of the segmenter")
    p.add_argument(
        "--stream-profile",
        choices=get_args(StreamProfile),
        default="reference",
        help="stream profile of the segmenter (causal: moment-axis words without waiting)",
    )
    p.add_argument(
        "--state-hold-s",
        type=float,
        default=0.0,
        help="classifier_node's state_hold_s: a new /task_state must hold this long (s)",
    )
    p.add_argument("--timeline", action="store_true", help="print the /task_state timeline")
    p.set_defaults(func=cmd_replay_eval)


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
    from rcbht_introspection.nodes.common import RosSession
    from rcbht_introspection.nodes.lifetime import StopSignal
    from rcbht_introspection.nodes.player import BagPlayer

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
    from rcbht_introspection.nodes.common import RosSession
    from rcbht_introspection.nodes.lifetime import StopSignal
    from rcbht_introspection.nodes.player import RawRecorder

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
        stream_profile=args.stream_profile,
        state_hold_s=args.state_hold_s,
    )
    result = replay_eval(_bags(args.bags), args.model, options)
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2))
    print(summary(result, timeline=args.timeline))
    return 0

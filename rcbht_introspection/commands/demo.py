"""`rcbht demo --out DIR`: the main job end to end, live.

Simulate trials (the project's own simulator), train a sub-task model on most of them, convert
the held-out trials to bags, replay them through segmenter_node and classifier_node (separate
processes, real DDS), then print the /task_state timeline against the truth, the accuracy, and
save a plot. --task peg-in-hole simulates the second task (its own four sub-tasks, a noisy
100 Hz sensor). With --data hiro it uses the ../shared HIRO data instead (train on REAL trials
1-40, replay 41-46). It names every missing part instead of failing obscurely.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import time
from pathlib import Path

from rcbht_introspection.commands.sim import TASK_CHOICES
from rcbht_introspection.errors import InputError

PARTS: dict[str, tuple[str, str]] = {
    "rclpy": ("ROS 2 Jazzy runtime (rclpy)", "make setup installs the pinned ROS wheels"),
    "rcbht_interfaces": ("rcbht_interfaces messages", "make setup builds msg_defs/ into the venv"),
}
"""The ROS parts a pip-only install may lack (the demo runs both nodes)."""


def _have(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `demo` subcommand."""
    p = subparsers.add_parser("demo", help="simulate, train, replay through the ROS nodes, score")
    p.add_argument("--out", type=Path, default=Path("demo_out"))
    p.add_argument("--data", choices=("auto", "sim", "hiro"), default="auto",
                   help="auto or sim: the project's simulator; hiro: ../shared REAL HIRO trials")  # fmt: skip
    p.add_argument("--task", choices=TASK_CHOICES, default="snap-assembly",
                   help="simulated task (default snap-assembly; --data sim or auto only)")  # fmt: skip
    p.add_argument("--trials", type=int, default=12, help="simulated trials (default 12)")
    p.add_argument("--held-out", type=int, default=3, help="simulated trials replayed (default 3)")
    p.add_argument("--rate", type=float, default=5.0, help="replay speed factor (default 5)")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=cmd_demo)


def _step(text: str) -> None:
    print(f"== {text}", flush=True)


def cmd_demo(args: argparse.Namespace) -> int:
    from rcbht_introspection.io.hiro import find_trials, read_trial, shared_hiro

    missing = [f"{name} ({how})" for mod, (name, how) in PARTS.items() if not _have(mod)]
    use_sim = args.data in ("sim", "auto")
    if not use_sim and args.task != "snap-assembly":
        raise InputError("--task chooses a simulated task; --data hiro is the snap assembly")
    hiro = shared_hiro()
    if not use_sim and hiro is None:
        missing.append("REAL HIRO trials (../shared/data/hiro or $RCBHT_HIRO_DATA)")
    if missing:
        print("rcbht demo cannot run; missing:")
        for m in missing:
            print(f"  - {m}")
        return 1

    from rcbht_introspection.io.bags import write_trial_bag
    from rcbht_introspection.learn.data import load_trials
    from rcbht_introspection.learn.live import live_training
    from rcbht_introspection.learn.model_file import save_model
    from rcbht_introspection.plots.timeline import plot_timelines
    from rcbht_introspection.replay.harness import ReplayEvalOptions, replay_eval
    from rcbht_introspection.replay.scoring import summary

    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    if use_sim:
        from rcbht_introspection.sim.dataset import write_dataset

        if args.held_out < 1 or args.trials - args.held_out < 2:
            raise InputError("need --held-out >= 1 and at least 2 training trials", field="trials")
        what = "one-arm" if args.task == "snap-assembly" else f"{args.task} one-arm"
        _step(f"1. simulate {args.trials} {what} trials (seed {args.seed}) -> {out / 'sim'}")
        folders = write_dataset(
            out / "sim", args.trials, scenario="one-arm", seed=args.seed, task=args.task
        )
        train, held = folders[: -args.held_out], folders[-args.held_out :]
        source = "simulator"
    else:
        _step(f"1. the shared REAL HIRO trials in {hiro}")
        assert hiro is not None
        folders = find_trials([hiro])
        train = [f for f in folders if int(f.name.rsplit("-", 1)[1]) <= 40]
        held = [f for f in folders if int(f.name.rsplit("-", 1)[1]) > 40]
        source = "REAL HIRO (shared data)"
    _step(f"2. train an SVM on {len(train)} trials (plus live windows: config/live.yaml)")
    trials = load_trials(train, words="auto")
    model, n_live = live_training(
        trials, classifier="svm", encoding="compact", random_state=args.seed
    )
    model_path = save_model(model, out / "model.rcbht")
    n_samples = sum(len(t.samples) for t in trials)
    print(
        f"   {model_path}: classes {model.classes_}, {n_samples} sub-task samples "
        f"+ {n_live} live windows"
    )
    _step(f"3. convert {len(held)} held-out trials to bags -> {out / 'bags'}")
    bags = []
    durations = {}
    for folder in held:
        trial = read_trial(folder)
        bag = out / "bags" / f"{folder.name}.mcap"
        if bag.exists():
            bag.unlink()
        write_trial_bag(trial, bag)
        bags.append(bag)
        durations[trial.name] = float(trial.time[-1] - trial.time[0])
    _step(
        f"4. replay at {args.rate}x through segmenter_node + classifier_node "
        "(separate processes, real DDS, localhost only)"
    )
    result = replay_eval(bags, model_path, ReplayEvalOptions(rate=args.rate, log_dir=out / "logs"))
    result["source"] = source
    (out / "replay_eval.json").write_text(json.dumps(result, indent=2))
    _step("5. /task_state timeline against the truth")
    print(summary(result, timeline=True))
    plot = plot_timelines(result, out / "task_state_timeline.png", durations)
    print(f"plot: {plot}")
    print(f"scores: {out / 'replay_eval.json'}  ({time.monotonic() - started:.0f} s in all)")
    return 0

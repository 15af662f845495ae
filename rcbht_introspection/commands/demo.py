"""`rcbht demo --out DIR`: the main job end to end, live.

Simulate trials (the project's own simulator), train a sub-task model on most of them, convert
the held-out trials to bags, replay them through segmenter_node and classifier_node (separate
processes, real DDS), then print the /task_state timeline against the truth, the accuracy, and
save a plot. With the simulated snap assembly it then trains a verifier on the repeated-program
cell, replays a nominal and a failing trial through verifier_node, and ends with the closed
loop: a failing cell trial run by sim_node, recovered by planner_node (all five nodes as
processes of their own) and its timeline figure. --task peg-in-hole simulates the second task (its own four sub-tasks, a noisy
100 Hz sensor). With --data hiro it uses the ../shared HIRO data instead (train on REAL trials
1-40, replay 41-46). It names every missing part instead of failing obscurely.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import time
from pathlib import Path
from typing import TYPE_CHECKING

from rcbht_introspection.commands.sim import TASK_CHOICES
from rcbht_introspection.errors import InputError

if TYPE_CHECKING:
    from rcbht_introspection.io.trial import Trial
    from rcbht_introspection.verify.model_file import VerifierModel

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


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
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
    """Run the demo's steps in order (module docstring); 1, naming them, when parts are missing."""
    from rcbht_introspection.io.hiro import shared_hiro

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

    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    if use_sim:
        train, held, source = _simulated_set(args, out)
    else:
        assert hiro is not None
        train, held, source = _shared_set(hiro)
    model_path = _train_model(args, train, out)
    bags, durations = _held_out_bags(held, out)
    _replay(args, bags, model_path, out, source, durations)
    if use_sim and args.task == "snap-assembly":
        verifier_path = _verify_demo(args, out, model_path)
        _closed_loop_demo(args, out, model_path, verifier_path)
    else:
        print("(verification: the simulated snap assembly only; it has failure trials)")
    print(f"scores: {out / 'replay_eval.json'}  ({time.monotonic() - started:.0f} s in all)")
    return 0


def _simulated_set(args: argparse.Namespace, out: Path) -> tuple[list[Path], list[Path], str]:
    """Step 1 with the simulator: the training and held-out trial folders, and their source."""
    from rcbht_introspection.sim.dataset import write_dataset

    if args.held_out < 1 or args.trials - args.held_out < 2:
        raise InputError("need --held-out >= 1 and at least 2 training trials", field="trials")
    what = "one-arm" if args.task == "snap-assembly" else f"{args.task} one-arm"
    _step(f"1. simulate {args.trials} {what} trials (seed {args.seed}) -> {out / 'sim'}")
    folders = write_dataset(
        out / "sim", args.trials, scenario="one-arm", seed=args.seed, task=args.task
    )
    return folders[: -args.held_out], folders[-args.held_out :], "simulator"


def _shared_set(hiro: Path) -> tuple[list[Path], list[Path], str]:
    """Step 1 with the shared REAL HIRO trials: 1-40 train, 41-46 are replayed."""
    from rcbht_introspection.io.hiro import find_trials

    _step(f"1. the shared REAL HIRO trials in {hiro}")
    folders = find_trials([hiro])
    train = [f for f in folders if int(f.name.rsplit("-", 1)[1]) <= 40]
    held = [f for f in folders if int(f.name.rsplit("-", 1)[1]) > 40]
    return train, held, "REAL HIRO (shared data)"


def _train_model(args: argparse.Namespace, train: list[Path], out: Path) -> Path:
    """Step 2: the sub-task model (words + wrench, with live windows) trained and saved in `out`."""
    from rcbht_introspection.learn.data import load_trials
    from rcbht_introspection.learn.live import live_training
    from rcbht_introspection.learn.model_file import save_model

    _step(f"2. train a words + wrench model on {len(train)} trials (plus live windows)")
    trials = load_trials(train, words="auto")
    model, n_live = live_training(trials, encoding="words-wrench", random_state=args.seed)
    model_path = save_model(model, out / "model.rcbht")
    n_samples = sum(len(t.samples) for t in trials)
    print(
        f"   {model_path}: classes {model.classes_}, {n_samples} sub-task samples "
        f"+ {n_live} live windows"
    )
    return model_path


def _held_out_bags(held: list[Path], out: Path) -> tuple[list[Path], dict[str, float]]:
    """Step 3: the held-out trials as bags, and each trial's duration (for the plot)."""
    from rcbht_introspection.io.bags import write_trial_bag
    from rcbht_introspection.io.hiro import read_trial

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
    return bags, durations


def _replay(
    args: argparse.Namespace,
    bags: list[Path],
    model_path: Path,
    out: Path,
    source: str,
    durations: dict[str, float],
) -> None:
    """Steps 4 and 5: replay the bags through the nodes, save the scores, print and plot the
    /task_state timeline."""
    from rcbht_introspection.plots.timeline import plot_timelines
    from rcbht_introspection.replay.harness import ReplayEvalOptions, replay_eval
    from rcbht_introspection.replay.scoring import summary

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


DEMO_FAILURES = ("deviation_x+", "jamming")
"""Failure classes the demo's verifier learns; the held-out failing trial is of the first."""
CELL_SUCCESSES = 12
"""Successful cell trials the demo's verifier learns from (config/sim/cell.yaml)."""


def _verify_demo(args: argparse.Namespace, out: Path, model_path: Path) -> Path:
    """Train a verifier on simulated trials of the repeated-program cell (config/sim/cell.yaml:
    a success spread narrow enough for a slipped part to show at its first contact), then replay
    one nominal and one failing held-out cell trial through the nodes with verifier_node."""
    from rcbht_introspection.io.bags import write_trial_bag
    from rcbht_introspection.replay.harness import ReplayEvalOptions, replay_eval
    from rcbht_introspection.replay.verify_scoring import verifier_summary

    verifier, verifier_path, replayed = _train_cell_verifier(args, out)
    _step("7. replay one nominal and one failing held-out trial with verifier_node")
    bags = []
    for trial in replayed:
        bag = out / "bags_verify" / f"{trial.name}.mcap"
        bag.unlink(missing_ok=True)
        write_trial_bag(trial, bag)
        bags.append(bag)
    result = replay_eval(
        bags,
        model_path,
        ReplayEvalOptions(rate=args.rate, log_dir=out / "logs_verify", verifier_file=verifier_path),
    )
    (out / "verify_eval.json").write_text(json.dumps(result["verifier"], indent=2))
    print(verifier_summary(result["verifier"]))
    for trial in replayed:
        print(f"plot: {_plot_verdicts(trial, verifier, out)}")
    return verifier_path


CLOSED_LOOP_CLASS = "deviation_x+"
"""The failing world the closed-loop step recovers from: the part slipped +x in the hand."""


def _closed_loop_demo(
    args: argparse.Namespace, out: Path, model_path: Path, verifier_path: Path
) -> None:
    """Step 8: one failing cell trial through the five nodes: the verifier's alarm, the abort,
    the correction from the named class, the retry; its decisions and timeline figure."""
    from rcbht_introspection.plots.closed_loop import plot_closed_loop
    from rcbht_introspection.replay.closed_loop import RosLoopOptions, run_over_ros

    _step("8. close the loop: sim_node runs a failing cell trial, planner_node recovers it")
    seed = 1000 * (args.seed + 1) + 197
    options = RosLoopOptions(
        out / "closed_loop", "introspect", str(verifier_path), model_file=str(model_path),
        rate_factor=args.rate, record=True,
    )  # fmt: skip
    runs, codes = run_over_ros([(seed, CLOSED_LOOP_CLASS)], options)
    trial = runs[0]
    for d in trial.decisions:
        c = ", ".join(f"{a} {v:+.4f}" for a, v in d["correction"].items() if v)
        what = d["failure_class"] or d["reason"]
        print(f"   {d['kind']:>7} attempt {d['attempt']} at {d['time']:.2f} s: {what} {c}")
    (out / "closed_loop.json").write_text(
        json.dumps({"seed": seed, "class": CLOSED_LOOP_CLASS, "decisions": trial.decisions,
                    "exit_codes": codes}, indent=2)
    )  # fmt: skip
    if trial.timeline is not None:
        title = f"closed loop, cell trial {seed} ({CLOSED_LOOP_CLASS})"
        print(
            f"plot: {plot_closed_loop(trial.timeline, title, out / 'closed_loop_timeline.png', args.rate)}"
        )


def _train_cell_verifier(
    args: argparse.Namespace, out: Path
) -> tuple[VerifierModel, Path, tuple[Trial, Trial]]:
    """Step 6: simulate the cell's trials, train and save the verifier; with the held-out
    nominal and failing trials it has not seen."""
    from rcbht_introspection.config_files import config_path
    from rcbht_introspection.sim import load_sim_config, simulate_trial
    from rcbht_introspection.verify.config import load_verify_config
    from rcbht_introspection.verify.labels import label_of
    from rcbht_introspection.verify.model_file import save_verifier
    from rcbht_introspection.verify.train import train_verifier

    sim = load_sim_config(config_path("sim/cell.yaml"))
    base = 1000 * (args.seed + 1)
    successes = [
        simulate_trial(sim, base + 100 + i, name=f"CELL-S-{i + 1:02d}")
        for i in range(CELL_SUCCESSES)
    ]
    failures = [
        simulate_trial(sim, base + i, failure=cls, name=f"CELL-F-{i + 1:02d}-{cls}")
        for i, cls in enumerate(DEMO_FAILURES * 2)
    ]
    nominal = simulate_trial(sim, base + 198, name="CELL-S-98-held")
    failing = simulate_trial(sim, base + 199, failure=DEMO_FAILURES[0], name="CELL-F-99-held")
    _step(
        f"6. train a verifier on {len(successes)} successes and {len(failures)} failures "
        f"({', '.join(DEMO_FAILURES)}) of one robot program repeated (config/sim/cell.yaml)"
    )
    trials = successes + failures
    verifier = train_verifier(trials, {t.name: label_of(t) for t in trials}, load_verify_config())
    verifier_path = save_verifier(verifier, out / "verifier.npz")
    print(f"   {verifier_path}: {json.dumps(verifier.trained_on)}")
    return verifier, verifier_path, (nominal, failing)


def _plot_verdicts(trial: Trial, verifier: VerifierModel, out: Path) -> Path:
    """The failure timeline of `trial`: the verdicts verifier_node published for it, tick for
    tick (computed offline), against its label."""
    import numpy as np

    from rcbht_introspection.plots.failure_timeline import plot_failure_timeline
    from rcbht_introspection.taxonomy.batch import label_trial
    from rcbht_introspection.verify.labels import label_of
    from rcbht_introspection.verify.stream import offline_verdicts

    verdicts = offline_verdicts(trial, verifier)  # what verifier_node published, tick for tick
    label = label_of(trial)
    return plot_failure_timeline(
        trial,
        label_trial(trial),
        np.array([v.time for v in verdicts]),
        np.array([v.score for v in verdicts]),
        verdicts[-1].alarm_time if verdicts else None,
        verdicts[-1].onset if verdicts else None,
        [(v.time, v.failure_class) for v in verdicts if v.alarm][::10],
        label.failure_class or "success",
        label.onset,
        out / f"failure_timeline_{trial.name}.png",
    )

"""ROS benchmark: sustained wrench rate with zero drops and word-to-belief latency, real DDS.

Two scenarios through segmenter_node + classifier_node as separate processes (the replay-eval
machinery): one arm at 1 kHz and two arms at 2 x 1 kHz, each for RCBHT_BENCH_ROS_SECONDS of
playback (default 60), with the nodes' default spin (rclpy's EventsExecutor) and again with
`spin: executor` (its SingleThreadedExecutor) on the same bags (latency and each node's CPU per
sample); a third plays the one-arm bags with verifier_node beside them, giving
sample -> verdict latency (the verifier's input is the wrench, not the words) beside word ->
belief in the same run. The verifier is trained on other successful trials (detection only).
A fourth plays the one-arm trials (at least three) to a classifier started without a model and
taught each but the last through its ~/teach service while the next plays (replay-eval
--teach-first --teach-beside): sample -> belief latency with teaching beside the live path, and
on the last trial with the taught model alone. The wrench comes from REAL HIRO trials (200 Hz
recordings played at 5x = 1 kHz) when ../shared data is present, else from a synthetic contact
signal. The classifier uses the default `rcbht train` model (with its live head) of HIRO trials
1-40 when the data are present, else none; RCBHT_BENCH_ROS_MODEL names a model file to use
instead (skips the training).
"""

from __future__ import annotations

import os
import re
import shutil
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from rcbht_introspection.bench.dds_floor import run_floor
from rcbht_introspection.configure.spin import Spin
from rcbht_introspection.errors import InputError
from rcbht_introspection.io.bags import write_trial_bag
from rcbht_introspection.io.hiro import find_trials, read_trial, shared_hiro
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.learn.data import load_trials
from rcbht_introspection.learn.live import live_training
from rcbht_introspection.learn.model_file import save_model
from rcbht_introspection.replay.harness import ReplayEvalOptions, replay_eval
from rcbht_introspection.verify.config import load_verify_config
from rcbht_introspection.verify.labels import SUCCESS, TrialLabel
from rcbht_introspection.verify.model_file import save_verifier
from rcbht_introspection.verify.train import train_verifier

SOURCE_RATE_HZ = 200.0
TARGET_RATE_HZ = 1000.0


def synthetic_trial(name: str, seconds: float, seed: int) -> Trial:
    """A 200 Hz contact-like wrench (ramps, holds, noise) with four sub-tasks."""
    rng = np.random.default_rng(seed)
    t = np.round(np.arange(0.0, seconds, 1.0 / SOURCE_RATE_HZ), 6)
    knots = np.sort(rng.uniform(0, seconds, 40))
    wrench = np.column_stack(
        [np.interp(t, knots, rng.normal(0, s, len(knots))) for s in (5, 5, 20, 0.5, 0.5, 0.2)]
    )
    wrench += rng.normal(0, 0.05, wrench.shape)
    marks = (0.0, 0.3 * seconds, 0.3 * seconds + 0.5, 0.55 * seconds)
    return Trial(name, t, {"R": wrench}, state_times=marks)


def _sources(seconds_of_data: float, at_least: int = 1) -> list[Trial]:
    """Trials (200 Hz) totalling at least `seconds_of_data`, at least `at_least` of them."""
    hiro = shared_hiro()
    trials: list[Trial] = []
    total = 0.0
    folders = find_trials([hiro]) if hiro is not None else []
    i = 0
    while total < seconds_of_data or len(trials) < at_least:
        if folders:
            trial = read_trial(folders[(40 + i) % len(folders)])  # held-out trials first
        else:
            trial = synthetic_trial(f"synthetic-{i}", 30.0, i)
        trials.append(trial)
        total += trial.end_time
        i += 1
    return trials


def two_arm_trial(a: Trial, b: Trial) -> Trial:
    """Arm R from `a`, arm L from `b` (cut or tiled to a's length)."""
    n = len(a.time)
    idx = np.arange(n) % len(b.time)
    return Trial(a.name, a.time, {"R": a.wrench["R"], "L": b.wrench["R"][idx]}, a.state_times)


def bench_model(out_dir: Path) -> Path | None:
    """The model `rcbht train` writes by default (live head included) for HIRO trials 1-40."""
    hiro = shared_hiro()

    if hiro is None:
        return None
    train = [f for f in find_trials([hiro]) if int(f.name.rsplit("-", 1)[1]) <= 40]
    model, _ = live_training(load_trials(train, "auto"))
    return save_model(model, out_dir / "bench_model.rcbht")


VERIFIER_TRIALS = 10
"""Successful trials the bench verifier is trained on (HIRO 1-10, else synthetic)."""


def bench_verifier(out_dir: Path) -> Path:
    """A verifier of successful trials not played in the bench (HIRO 1-10, else synthetic)."""
    hiro = shared_hiro()
    if hiro is not None:
        folders = [f for f in find_trials([hiro]) if int(f.name.rsplit("-", 1)[1]) <= 40]
        trials = [read_trial(f) for f in folders[:VERIFIER_TRIALS]]
    else:
        trials = [synthetic_trial(f"train-{i}", 30.0, 100 + i) for i in range(VERIFIER_TRIALS)]
    labels = {t.name: TrialLabel(t.name, SUCCESS) for t in trials}
    model = train_verifier(trials, labels, load_verify_config())
    return save_verifier(model, out_dir / "bench_verifier.npz")


def model_from_env(name: str, out_dir: Path) -> Path | None:
    """The model file named by the environment variable `name` (training skipped, so that runs
    can share one), else bench_model's."""
    text = os.environ.get(name, "").strip()
    if not text:
        return bench_model(out_dir)
    if not Path(text).is_file():
        raise InputError("no such model file", text, field=name)
    return Path(text)


def _scenario_bags(work: Path, name: str, arms: int, sources: list[Trial]) -> list[Path]:
    """The trial bags of a scenario, written under work/name (two arms: each trial's arm R
    beside the next one's)."""
    bags = []
    for i, trial in enumerate(sources):
        if arms == 2:
            trial = two_arm_trial(trial, sources[(i + 1) % len(sources)])
        bags.append(work / name / f"{i:02d}-{trial.name}.mcap")
        write_trial_bag(trial, bags[-1])
    return bags


SCENARIOS: tuple[tuple[str, int, bool, Spin], ...] = (
    ("one_arm_1kHz", 1, False, "events"),
    ("two_arm_2x1kHz", 2, False, "events"),
    ("one_arm_1kHz_verifier", 1, True, "events"),
    ("one_arm_1kHz_executor", 1, False, "executor"),
    ("two_arm_2x1kHz_executor", 2, False, "executor"),
    ("one_arm_1kHz_verifier_executor", 1, True, "executor"),
)
"""(name, arms, with verifier_node, the nodes' spin): the default spin (EventsExecutor), then
rclpy's SingleThreadedExecutor on the same bags (`RCBHT_BENCH_ROS_SPINS`: a comma-separated
subset of the spins, default both)."""


def run(out_dir: Path) -> dict[str, Any]:
    """The DDS floor, then each scenario; figures per scenario, their latency p99 as a ratio to
    the floor's p99, and the load average around them."""
    seconds = float(os.environ.get("RCBHT_BENCH_ROS_SECONDS", "60"))
    rate = TARGET_RATE_HZ / SOURCE_RATE_HZ
    work = Path(out_dir) / "ros"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    model = model_from_env("RCBHT_BENCH_ROS_MODEL", work)
    sources = _sources(seconds * rate)
    results: dict[str, Any] = {
        "playback_seconds_target": seconds,
        "source": "REAL HIRO trials at 5x" if shared_hiro() else "synthetic 200 Hz at 5x",
        "model": str(model) if model else None,
    }
    verifier = bench_verifier(work)
    results["verifier"] = str(verifier)
    results["dds_floor_1kHz"] = floor = _timed(run_floor, TARGET_RATE_HZ, seconds)
    bags = {arms: _scenario_bags(work, f"{arms}_arm", arms, sources) for arms in (1, 2)}
    spins = os.environ.get("RCBHT_BENCH_ROS_SPINS", "events,executor").split(",")
    for name, arms, verifier_file, spin in SCENARIOS:
        if spin not in spins:
            continue
        options = ReplayEvalOptions(
            rate=rate,
            offline=False,
            log_dir=work / f"{name}_logs",
            verifier_file=verifier if verifier_file else None,
            spin=spin,
        )
        results[name] = _timed(_scenario, bags[arms], model, options, arms)
        results[name]["latency_p99_over_floor"] = _over(results[name]["latency_ms"], floor)
    results["one_arm_1kHz_teaching"] = _teaching_beside(sources, rate, work)
    return results


def _over(latency: dict[str, Any], floor: dict[str, Any]) -> float | None:
    """A latency's p99 as a multiple of the DDS floor's p99."""
    p99, base = latency.get("p99"), floor["latency_ms"].get("p99")
    return round(p99 / base, 2) if p99 is not None and base else None


def _timed(measure: Callable[..., dict[str, Any]], *args: Any) -> dict[str, Any]:
    """A measurement's figures with its wall time and the load average before and after."""
    load_before = os.getloadavg()
    t0 = time.monotonic()
    figures = measure(*args)
    figures["wall_s"] = round(time.monotonic() - t0, 1)
    figures["load_avg_before"] = [round(x, 2) for x in load_before]
    figures["load_avg_after"] = [round(x, 2) for x in os.getloadavg()]
    return figures


def _scenario(
    bags: list[Path], model: Path | None, options: ReplayEvalOptions, arms: int
) -> dict[str, Any]:
    """One scenario's figures: its bags replayed through the node processes."""
    r = replay_eval(bags, model, options)
    play_s = sum(b["play_s"] for b in r["per_bag"])
    published = sum(b["published_wrench"] for b in r["per_bag"])
    figures = {
        "arms": arms,
        "wrench_published": published,
        "wrench_dropped": r["dropped_wrench"],
        "wrench_rejected": r["rejected_wrench"],
        "playback_s": round(play_s, 2),
        "achieved_rate_hz_per_arm": round(published / arms / play_s, 1) if play_s else None,
        "latency_ms": r["latency_ms"],
        "latency_received_ms": r["latency_received_ms"],
        "word_latency_ms": r["word_latency_ms"],
        "clean_shutdown": r["clean_shutdown"],
        "exit_codes": r["exit_codes"],
        "shutdown_logs": r.get("shutdown_logs", {}),
        "domain_id": r["domain_id"],
    }
    if options.log_dir is not None and published:
        figures["spin"] = options.spin
        figures["cpu_us_per_sample"] = {
            node: round(cpu_s / published * 1e6, 1)
            for node, cpu_s in node_cpu_s(Path(options.log_dir)).items()
        }
    if "verifier" in r:
        figures["sample_to_verdict_ms"] = r["verifier"]["sample_to_verdict_ms"]
        figures["verdicts"] = sum(v["verdicts"] for v in r["verifier"]["runs"])
    return figures


CPU_LINE = re.compile(r"CPU ([0-9.]+) s after")
"""The CPU time a node logs in its last line (statistics at deactivate)."""


def node_cpu_s(log_dir: Path) -> dict[str, float]:
    """Each node's process CPU seconds as it logged them when it stopped (its last CPU line)."""
    out = {}
    for log in sorted(log_dir.glob("*_node.log")):
        found = CPU_LINE.findall(log.read_text(errors="replace"))
        if found:
            out[log.stem] = float(found[-1])
    return out


def _teaching_beside(sources: list[Trial], rate: float, work: Path) -> dict[str, Any]:
    """The one-arm bags (at least three: more trials are written when a short run has fewer)
    to a cold-started classifier, each but the last taught while the next one plays; the
    latency beside teaching, and on the last trial with the taught model alone."""
    bags = [work / "1_arm" / f"{i:02d}-{t.name}.mcap" for i, t in enumerate(sources)]
    extra = _sources(0.0, at_least=3)[len(bags) :] if len(bags) < 3 else []
    for i, trial in enumerate(extra, start=len(bags)):
        bags.append(work / "one_arm_1kHz_teaching" / f"{i:02d}-{trial.name}.mcap")
        write_trial_bag(trial, bags[-1])
    load_before = os.getloadavg()
    t0 = time.monotonic()
    options = ReplayEvalOptions(
        rate=rate,
        offline=False,
        log_dir=work / "one_arm_1kHz_teaching_logs",
        teach_first=len(bags) - 1,
        teach_beside=True,
    )
    r = replay_eval(bags, None, options)
    teach = r["teach"]
    return {
        "taught_trials": len(teach["taught_trials"]),
        "taught_windows": teach["taught_windows"],
        "teach_errors": teach["errors"],
        "learned_per_trial_s": teach["trial_latency_s"],
        "latency_beside_teaching_ms": teach["latency_beside_ms"],
        "latency_taught_model_ms": r["latency_ms"],
        "wrench_dropped": r["dropped_wrench"],
        "clean_shutdown": r["clean_shutdown"],
        "wall_s": round(time.monotonic() - t0, 1),
        "load_avg_before": [round(x, 2) for x in load_before],
        "load_avg_after": [round(x, 2) for x in os.getloadavg()],
    }

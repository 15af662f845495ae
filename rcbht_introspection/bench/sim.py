"""Simulator speed: seconds per simulated trial (median) and the wall time of the demo's data set."""

from __future__ import annotations

import shutil
import statistics
import time
from pathlib import Path

from rcbht_introspection.sim import load_sim_config, simulate_trial, write_dataset
from rcbht_introspection.sim.config import SimConfig

DEMO_TRIALS = 12
"""The demo's data set: 12 one-arm trials at 200 Hz (what `make demo` generates)."""


def _per_trial(config: SimConfig, scenario: str, rate_hz: float, seeds: range) -> dict[str, float]:
    times, sim_seconds = [], []
    for seed in seeds:
        start = time.perf_counter()
        trial = simulate_trial(config, seed, scenario, rate_hz=rate_hz)
        times.append(time.perf_counter() - start)
        sim_seconds.append(trial.end_time)
    return {
        "trials": len(times),
        "median_s_per_trial": round(statistics.median(times), 4),
        "max_s_per_trial": round(max(times), 4),
        "median_simulated_s": round(statistics.median(sim_seconds), 2),
        "real_time_factor": round(statistics.median(sim_seconds) / statistics.median(times), 1),
    }


def run(out_dir: Path) -> dict[str, object]:
    """Measure per-trial cost (one-arm, two-arm, 1 kHz) and the demo data set's wall time."""
    config = load_sim_config()
    results: dict[str, object] = {
        "one_arm_200hz": _per_trial(config, "one-arm", 200.0, range(100, 108)),
        "two_arm_200hz": _per_trial(config, "two-arm", 200.0, range(200, 204)),
        "one_arm_1khz": _per_trial(config, "one-arm", 1000.0, range(300, 303)),
    }
    target = Path(out_dir) / "sim_demo_data"
    shutil.rmtree(target, ignore_errors=True)
    start = time.perf_counter()
    write_dataset(target, DEMO_TRIALS, scenario="one-arm", seed=7, config=config)
    results["demo_dataset"] = {
        "trials": DEMO_TRIALS,
        "scenario": "one-arm",
        "rate_hz": 200.0,
        "wall_s": round(time.perf_counter() - start, 3),
        "budget_s": 30.0,
    }
    shutil.rmtree(target, ignore_errors=True)
    return results

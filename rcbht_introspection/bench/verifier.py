"""Verifier cost per tick, offline, no ROS: what verifier_node's state (VerifierSession) spends
on each verdict before the alarm and as the evidence after it grows.

A verifier is trained on the project's simulated cell (config/sim_cell.yaml: TRAIN_SUCCESSES
successes, FAILURES_PER_CLASS failures of every class). A held-out failing trial is fed as the
node is fed a replayed bag, then its last sample is held for HOLD_S more seconds of stream time
(a robot left in contact after the alarm): every tick after the alarm names the class again
from the whole evidence since onset, so its cost must not grow with that evidence.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from rcbht_introspection.config_files import config_path
from rcbht_introspection.io.bags import trial_phase_events
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.sim import load_sim_config, simulate_trial
from rcbht_introspection.sim.config import SimConfig, failure_classes
from rcbht_introspection.verify.config import load_verify_config
from rcbht_introspection.verify.labels import label_of
from rcbht_introspection.verify.monitor import VerifierSession
from rcbht_introspection.verify.train import train_verifier

TRAIN_SUCCESSES = 12
FAILURES_PER_CLASS = 2
HOLD_S = float(os.environ.get("RCBHT_BENCH_VERIFIER_HOLD_S", "600"))
"""Stream seconds the held-out trial's last sample is held after its end."""
WINDOW_S = 10.0
"""Per-tick figures over the first WINDOW_S after the alarm and the last WINDOW_S of the hold."""
TEST_SEEDS = range(9000, 9010)
TEST_CLASS = "deviation_x+y+"


def _train_set() -> tuple[list[Trial], SimConfig]:
    config = load_sim_config(config_path("sim_cell.yaml"))
    trials = [simulate_trial(config, seed, name=f"S-{seed}") for seed in range(TRAIN_SUCCESSES)]
    for k, failure in enumerate(failure_classes(config.failures)):
        for j in range(FAILURES_PER_CLASS):
            seed = 1000 + FAILURES_PER_CLASS * k + j
            trials.append(simulate_trial(config, seed, failure=failure, name=f"F-{seed}"))
    return trials, config


def _feed(session: VerifierSession, trial: Trial, hold_s: float) -> list[tuple[float, float]]:
    """(tick time - alarm time, seconds spent) per verdict, for the ticks after the alarm; the
    trial's samples, then its last one held for hold_s."""
    t0 = float(trial.time[0])
    times = np.asarray(trial.time) - t0
    events = [(t - t0, n) for t, n in trial_phase_events(trial) if n != "done"]
    dt = float(np.median(np.diff(times)))
    arm = trial.arms[0]
    wrench = np.asarray(trial.wrench[arm])
    out: list[tuple[float, float]] = []
    k = 0
    clock = time.perf_counter
    n_held = round(hold_s / dt)
    for i in range(len(times) + n_held):
        t = float(times[i]) if i < len(times) else float(times[-1]) + (i - len(times) + 1) * dt
        while k < len(events) and events[k][0] <= t:
            session.phase(events[k][1], events[k][0])
            k += 1
        began = clock()
        verdicts = session.push(arm, t, wrench[min(i, len(times) - 1)])
        spent = clock() - began
        for v in verdicts:
            if v.alarm_time is not None and v.time > v.alarm_time:
                out.append((v.time - v.alarm_time, spent / len(verdicts)))
    return out


def _stats(seconds: list[float]) -> dict[str, float]:
    ms = 1000.0 * np.asarray(seconds)
    return {
        "ticks": len(ms),
        "median_ms": round(float(np.median(ms)), 3),
        "p99_ms": round(float(np.percentile(ms, 99)), 3),
        "max_ms": round(float(ms.max()), 3),
    }


def run(out_dir: Path) -> dict[str, Any]:
    """Median / p99 / max ms per tick after the alarm: its first WINDOW_S and the hold's last."""
    began = time.perf_counter()
    trials, sim_config = _train_set()
    labels = {t.name: label_of(t) for t in trials}
    model = train_verifier(trials, labels, load_verify_config())
    trained_s = time.perf_counter() - began
    for seed in TEST_SEEDS:
        trial = simulate_trial(sim_config, seed, failure=TEST_CLASS, name=f"T-{seed}")
        ticks = _feed(VerifierSession(model), trial, HOLD_S)
        if ticks:
            break
    else:
        return {"skipped": f"no held-out {TEST_CLASS} trial raised the alarm"}
    last = max(t for t, _ in ticks)
    return {
        "trained_on": model.trained_on,
        "train_s": round(trained_s, 1),
        "test_trial": trial.name,
        "evidence_s_at_end": round(last, 1),
        "first_window": _stats([s for t, s in ticks if t <= WINDOW_S]),
        "last_window": _stats([s for t, s in ticks if t > last - WINDOW_S]),
    }

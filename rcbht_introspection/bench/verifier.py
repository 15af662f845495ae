"""Verifier cost per tick after the alarm, offline, no ROS: what verifier_node's state
(VerifierSession) spends on each verdict once the evidence runs.

A verifier reading every signal (VERIFIER_SIGNALS: the most a user can configure) is trained
on the project's simulated cell (config/sim/cell.yaml: TRAIN_SUCCESSES successes,
FAILURES_PER_CLASS failures of every class). A held-out failing trial is fed as the
node is fed a replayed bag, then its last sample is held for HOLD_S more seconds of stream time
(a robot left in contact after the alarm). Every tick after the alarm adds to the running
evidence; the characteriser names the class only at the alarm, at each tick that opens an
evidence span (config/verify.yaml evidence_s) and at the end. So the figures are the median and
p99 per tick over all ticks after the alarm, the naming ticks apart from the others, and the
hold's last WINDOW_S (the cost must not grow with the evidence).
"""

from __future__ import annotations

import dataclasses
import itertools
import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from rcbht_introspection.bench.durations import ms_summary
from rcbht_introspection.config_files import config_path
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.sim import load_sim_config, simulate_trial
from rcbht_introspection.sim.config import SimConfig, failure_classes
from rcbht_introspection.verify.config import VERIFIER_SIGNALS, load_verify_config
from rcbht_introspection.verify.labels import label_of
from rcbht_introspection.verify.monitor import VerifierSession
from rcbht_introspection.verify.stream import sample_steps
from rcbht_introspection.verify.train import train_verifier

TRAIN_SUCCESSES = 12
FAILURES_PER_CLASS = 2
HOLD_S = float(os.environ.get("RCBHT_BENCH_VERIFIER_HOLD_S", "600"))
"""Stream seconds the held-out trial's last sample is held after its end."""
WINDOW_S = 10.0
"""Per-tick figures also over the last WINDOW_S of the hold."""
TEST_SEEDS = range(9000, 9010)
TEST_CLASS = "deviation_x+y+"


def _train_set() -> tuple[list[Trial], SimConfig]:
    config = load_sim_config(config_path("sim/cell.yaml"))
    trials = [simulate_trial(config, seed, name=f"S-{seed}") for seed in range(TRAIN_SUCCESSES)]
    for k, failure in enumerate(failure_classes(config.failures)):
        for j in range(FAILURES_PER_CLASS):
            seed = 1000 + FAILURES_PER_CLASS * k + j
            trials.append(simulate_trial(config, seed, failure=failure, name=f"F-{seed}"))
    return trials, config


def _feed(session: VerifierSession, trial: Trial, hold_s: float) -> list[tuple[float, float, bool]]:
    """(tick time - alarm time, seconds spent, named the class) per verdict, for the ticks after
    the alarm; the trial's samples, then its last one held for hold_s, then the end event."""
    times = np.asarray(trial.time, dtype=float) - float(trial.time[0])
    dt = float(np.median(np.diff(times)))
    arm = trial.arms[0]
    wrench = np.asarray(trial.wrench[arm])
    held: Iterator[tuple[int, float, list[tuple[float, str]]]] = (
        (len(times) - 1, float(times[-1]) + j * dt, []) for j in range(1, round(hold_s / dt) + 1)
    )
    out: list[tuple[float, float, bool]] = []
    clock = time.perf_counter
    for i, t, due in itertools.chain(sample_steps(trial), held):
        for when, name in due:
            session.phase(name, when)
        named = session.named
        began = clock()
        verdicts = session.push(arm, t, wrench[i])
        spent = clock() - began
        renamed = session.named is not named  # a new naming (a new tuple) in this push
        for v in verdicts:
            if v.alarm_time is not None and v.time >= v.alarm_time:
                out.append((v.time - v.alarm_time, spent / len(verdicts), renamed))
    named = session.named
    began = clock()
    verdicts = session.end()  # the end event: the last tick, named again
    spent = clock() - began
    for v in verdicts:
        if v.alarm_time is not None:
            out.append((v.time - v.alarm_time, spent / len(verdicts), session.named is not named))
    return out


def run(out_dir: Path) -> dict[str, Any]:
    """Median / p99 / max ms per tick from the alarm on: all ticks, the naming ticks, the others,
    and the hold's last WINDOW_S."""
    began = time.perf_counter()
    trials, sim_config = _train_set()
    labels = {t.name: label_of(t) for t in trials}
    config = dataclasses.replace(load_verify_config(), signals=VERIFIER_SIGNALS)
    model = train_verifier(trials, labels, config)
    trained_s = time.perf_counter() - began
    for seed in TEST_SEEDS:
        trial = simulate_trial(sim_config, seed, failure=TEST_CLASS, name=f"T-{seed}")
        ticks = _feed(VerifierSession(model), trial, HOLD_S)
        if ticks:
            break
    else:
        return {"skipped": f"no held-out {TEST_CLASS} trial raised the alarm"}
    last = max(t for t, _, _ in ticks)
    naming = [s for _, s, named in ticks if named]
    return {
        "trained_on": model.trained_on,
        "train_s": round(trained_s, 1),
        "test_trial": trial.name,
        "evidence_s_at_end": round(last, 1),
        "after_alarm": ms_summary([s for _, s, _ in ticks], "ticks"),
        "naming_ticks": ms_summary(naming, "ticks") if naming else {"ticks": 0},
        "other_ticks": ms_summary([s for _, s, named in ticks if not named], "ticks"),
        "last_window": ms_summary([s for t, s, _ in ticks if t > last - WINDOW_S], "ticks"),
    }

"""Teaching the live classifier, offline, no ROS: teach latency and belief updates beside teaching.

Teach latency: a cold-started Teaching (learn/teaching.py, the node's queue and worker) is taught
REAL S-31..40 streamed through the segmenter session, trial by trial with the true sub-task
windows: on odd trials each sub-task alone (one request, waited for: "one sub-task"), on even
trials all four at once ("whole trial"). Latency = request accepted -> taught model in the slot
the live path takes it from at its next belief update.

Belief updates beside teaching: the belief-update loop of bench/belief.py on REAL S-45/46 with
the taught model, once alone and then while a thread keeps learning ten trials' windows over and
over (what the teach worker does while labels are being learned): learning in that thread
(TeachConfig.learner 'thread') and in the learner's own process ('process', the default).
"""

from __future__ import annotations

import os
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from rcbht_introspection.bench.belief import (
    HIRO,
    REAL,
    TEST_TRIALS,
    feed_step,
    timed_updates,
)
from rcbht_introspection.bench.durations import ms_summary
from rcbht_introspection.grammar.split import SubtaskSample, window_sample
from rcbht_introspection.io.hiro import read_trial
from rcbht_introspection.learn.learner_process import ProcessLearner
from rcbht_introspection.learn.live import LiveAugmentConfig, load_live_config, stream_factory
from rcbht_introspection.learn.online import (
    LEARNERS,
    OnlineLearner,
    TeachConfig,
    load_teach_config,
)
from rcbht_introspection.learn.teaching import Teaching
from rcbht_introspection.live.belief import BeliefTracker
from rcbht_introspection.live.replay import StreamedTrial, stream_trial
from rcbht_introspection.live.teach import TeachRequest
from rcbht_introspection.waiting import wait_until

TAUGHT = tuple(f"20121127-HIROSA-S-{i:02d}" for i in range(31, 41))


def _fed(tracker: BeliefTracker, streamed: StreamedTrial, teaching: Teaching) -> None:
    """The whole trial into `tracker` (a new stream), taking taught models as the node does."""
    tracker.reset()
    for step in streamed.steps:
        model = teaching.take_model()
        if model is not None:
            tracker.set_model(model)
        feed_step(tracker, step)


def teach_latencies(streamed: list[StreamedTrial], config: TeachConfig) -> dict[str, Any]:
    """One-sub-task and whole-trial latencies of a cold-started Teaching (module doc)."""
    teaching = Teaching(config, live_windows=load_live_config())
    tracker = BeliefTracker(None, history_s=600.0)
    single: list[float] = []
    whole: list[float] = []
    try:
        for i, trial in enumerate(streamed):
            _fed(tracker, trial, teaching)
            windows = trial.subtask_windows()
            if i % 2 == 0:
                for name, start, end in windows:
                    before = len(teaching.latencies_s)
                    teaching.request(TeachRequest(name, False, start, end), tracker)
                    _wait_learned(teaching, before + 1)
                    single.append(teaching.latencies_s[-1])
            else:
                before = len(teaching.latencies_s)
                for name, start, end in windows:
                    teaching.request(TeachRequest(name, False, start, end), tracker)
                n = len(windows)
                _wait_learned(teaching, before + n)
                whole.append(max(list(teaching.latencies_s)[before:]))
        model = teaching.take_model() or tracker.model
    finally:
        teaching.close()
    status = teaching.status()
    return {
        "one_subtask_s": _seconds(single),
        "whole_trial_s": _seconds(whole),
        "taught_windows": status.taught_windows,
        "model_versions": status.model_version,
        "model": model,
    }


def _wait_learned(teaching: Teaching, jobs: int) -> None:
    """Until `jobs` requests in all are in a model in the slot (an update that failed, or none in
    600 s, ends the benchmark: its latency would be wrong)."""
    learned = wait_until(
        lambda: len(teaching.latencies_s) >= jobs or teaching.counts["teach updates failed"] > 0,
        timeout=600,
    )
    if not learned or teaching.counts["teach updates failed"]:
        raise RuntimeError(f"teaching did not learn {jobs} requests: {teaching.notes()}")


def _seconds(values: list[float]) -> dict[str, Any]:
    a = np.asarray(values)
    return {
        "n": len(a),
        "median": round(float(np.median(a)), 3),
        "max": round(float(a.max()), 3),
        "in_order": [round(float(v), 3) for v in a],
    }


def _samples(streamed: list[StreamedTrial]) -> list[SubtaskSample]:
    """The true sub-task windows of streamed trials (what a teacher labels)."""
    out = []
    for s in streamed:
        words = BeliefTracker(None, history_s=600.0)
        for step in s.steps:
            for b in step.batches:
                words.add_words(b.arm, b.words, (b.stamp_ns - b.origin_ns) / 1e9)
        for name, start, end in s.subtask_windows():
            out.append(window_sample(words.words, start, end, subtask=name, trial=s.name))
    return out


def updates_beside_teaching(
    held_out: list[StreamedTrial], model: Any, samples: list[SubtaskSample], config: TeachConfig
) -> dict[str, Any]:
    """Belief-update times alone and while a thread keeps learning `samples`, for each place
    the learning can run (TeachConfig.learner): in that thread, or in the learner's process
    the thread waits on (what the node's teach worker does)."""
    alone: list[float] = []
    for s in held_out:
        alone += timed_updates(s, model, "boundary")[0]
    out: dict[str, Any] = {"alone": ms_summary(alone, "updates")}
    for learner in LEARNERS:
        out[learner] = _updates_while_learning(
            held_out, model, samples, replace(config, learner=learner)
        )
    return out


def _updates_while_learning(
    held_out: list[StreamedTrial], model: Any, samples: list[SubtaskSample], config: TeachConfig
) -> dict[str, Any]:
    """Belief-update times while a thread teaches `samples` in fours to a fresh learner, pass
    after pass: learning in the thread itself, or in a ProcessLearner the thread waits on."""
    stop = threading.Event()
    rounds = [0]

    def learn() -> None:
        while not stop.is_set():
            process = ProcessLearner(config) if config.learner == "process" else None
            learner = OnlineLearner(config)
            try:
                for i in range(0, len(samples), 4):
                    if stop.is_set():
                        return
                    if process is not None:
                        process.teach(samples[i : i + 4])
                    else:
                        learner.teach(samples[i : i + 4])
                    rounds[0] += 1
            finally:
                if process is not None:
                    process.close()

    worker = threading.Thread(target=learn, daemon=True)
    worker.start()
    beside: list[float] = []
    t0 = time.perf_counter()
    try:
        for s in held_out:
            beside += timed_updates(s, model, "boundary")[0]
    finally:
        stop.set()
        worker.join()
    return {
        "beside_teaching": ms_summary(beside, "updates"),
        "teach_updates_during": rounds[0],
        "measured_s": round(time.perf_counter() - t0, 2),
    }


def run(out_dir: Path) -> dict[str, Any]:
    """Teach latencies and belief-update times with and without teaching (module doc)."""
    if not (HIRO / REAL).is_dir():
        return {"skipped": f"no shared data at {HIRO / REAL}"}
    factory = stream_factory(LiveAugmentConfig())
    taught = [stream_trial(read_trial(HIRO / REAL / n), factory) for n in TAUGHT]
    held_out = [stream_trial(read_trial(HIRO / REAL / n), factory) for n in TEST_TRIALS]
    config = load_teach_config()
    latencies = teach_latencies(taught, config)
    model = latencies.pop("model")
    updates = updates_beside_teaching(held_out, model, _samples(taught), config)
    return {
        "taught": [TAUGHT[0], TAUGHT[-1]],
        "held_out": list(TEST_TRIALS),
        "teach_config": {
            "n_estimators": config.n_estimators,
            "prefixes": list(config.prefixes),
            "warmup_windows": config.warmup_windows,
            "learner": config.learner,
        },
        "teach_latency": latencies,
        "belief_update_boundary": updates,
        "loadavg": [round(x, 2) for x in os.getloadavg()],
    }


if __name__ == "__main__":
    import json

    print(json.dumps(run(Path("bench_out")), indent=1))

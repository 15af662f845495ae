"""Belief-update latency of the classifier node's state (BeliefTracker), offline, no ROS.

One update = what classifier_node does per wrench sample with words (live/classifier.py): add
the words, apply the events, take final verdicts, classify the running window. Measured on a
REAL HIRO trial streamed through the segmenter session, with the model `rcbht train` writes by
default for REAL trials 1-40 (words + wrench with its live and window heads; the ROS
benchmark's model), in
boundary and window mode.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

from rcbht_introspection.bench.durations import ms_summary
from rcbht_introspection.io.hiro import find_trials, read_trial
from rcbht_introspection.learn.data import load_trials
from rcbht_introspection.learn.live import LiveAugmentConfig, live_training, stream_factory
from rcbht_introspection.live import MODES, BeliefMode
from rcbht_introspection.live.belief import BeliefTracker, SampleClassifier
from rcbht_introspection.live.replay import stream_trial

HIRO = Path(
    os.environ.get(
        "RCBHT_HIRO_DATA", Path(__file__).resolve().parents[2].parent / "shared" / "data" / "hiro"
    )
)
REAL = "REAL_HIRO_ONE_SA_SUCCESS"
TEST_TRIALS = ("20121127-HIROSA-S-45", "20121127-HIROSA-S-46")


def feed_step(tracker: BeliefTracker, step: Any) -> None:
    """One segmenter step of a streamed trial into `tracker`, as the classifier node takes it:
    its words, end markers and sub-task events, then the finished sub-tasks' verdicts."""
    for batch in step.batches:
        tracker.add_words(batch.arm, batch.words, (batch.stamp_ns - batch.origin_ns) / 1e9)
        if batch.end_of_stream:
            tracker.end_of_stream(batch.arm)
    for p in step.phases:
        tracker.phase(p.name, p.time)
    tracker.take_finals()


def timed_updates(
    streamed: Any, model: SampleClassifier, mode: BeliefMode
) -> tuple[list[float], list[str]]:
    """(seconds per update, belief sub-task per update) of the tracker fed `streamed` step by
    step (stream_trial's steps: a sample's words with the events after it)."""

    tracker = BeliefTracker(model, mode, 2.0, trial=streamed.name)
    times: list[float] = []
    states: list[str] = []
    clock = time.perf_counter
    for step in streamed.steps:
        began = clock()
        feed_step(tracker, step)
        states.append(tracker.current().subtask)
        times.append(clock() - began)
    return times, states


def run(out_dir: Path) -> dict[str, Any]:
    """Median / p99 / max ms per belief update, per mode, over the held-out REAL trials."""
    if not (HIRO / REAL).is_dir():
        return {"skipped": f"no shared data at {HIRO / REAL}"}

    train = [f for f in find_trials([HIRO / REAL]) if int(f.name.rsplit("-", 1)[1]) <= 40]
    model, _ = live_training(load_trials(train, "auto"))  # `rcbht train`'s default model
    factory = stream_factory(LiveAugmentConfig())
    streamed = [stream_trial(read_trial(HIRO / REAL / name), factory) for name in TEST_TRIALS]
    out: dict[str, Any] = {
        "trials": list(TEST_TRIALS),
        "model": f"{model.classifier}/{model.encoding} with its heads (rcbht train default), "
        "REAL 1-40",
    }
    for mode in MODES:
        times: list[float] = []
        for s in streamed:
            times += timed_updates(s, model, mode)[0]
        out[mode] = ms_summary(times, "updates")
    out["loadavg"] = [round(x, 2) for x in os.getloadavg()]
    return out


if __name__ == "__main__":
    import json

    print(json.dumps(run(Path("bench_out")), indent=1))

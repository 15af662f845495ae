"""The soak's traffic: two-arm trials re-stamped into one endless stream, the thread that publishes
them at 1 kHz per arm with their sub-task events, and the observer that counts what the nodes say."""

from __future__ import annotations

import functools
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from geometry_msgs.msg import WrenchStamped
from rcbht_interfaces.msg import Belief as BeliefMsg
from rcbht_interfaces.msg import Phase as PhaseMsg
from rcbht_interfaces.msg import Words as WordsMsg
from std_msgs.msg import String

from rcbht_introspection.bench import ros
from rcbht_introspection.configure.params import ClassifierConfig, SegmenterConfig, word_topics
from rcbht_introspection.io.bags import (
    END_PHASE,
    PHASE_TOPIC,
    encode_wrench,
    trial_phase_events,
    wrench_topic,
)
from rcbht_introspection.io.hiro import find_trials, read_trial, shared_hiro
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.replay.observer import DiagnosticWatch
from rcbht_introspection.sim import load_sim_config, simulate_trial

ARMS: tuple[str, ...] = ("L", "R")
TRIAL_GAP_S = 0.5
"""Pause between trials (the end event is applied after 0.2 s without samples)."""
SIM_TRIALS = 6
"""Distinct simulated trials played in turn when there is no HIRO data."""
LATE_MS = 10.0
"""A sample published this much after its due time counts as late (publisher, not nodes)."""


@dataclass(frozen=True)
class Source:
    """Where the trials come from: `trial(i)` is the i-th two-arm trial, played at `rate`."""

    name: str
    rate: float
    trial: Callable[[int], Trial]


def trial_source() -> Source:
    """REAL HIRO trials when present, else the simulator's two-arm trials; both at 5x."""

    hiro = shared_hiro()
    if hiro is not None:
        folders = find_trials([hiro])
        order = [folders[(40 + i) % len(folders)] for i in range(len(folders))]  # held out first
        read = functools.lru_cache(maxsize=len(order))(lambda k: read_trial(order[k]))

        def real(i: int) -> Trial:
            k = i % len(order)
            return ros.two_arm_trial(read(k), read((k + 1) % len(order)))

        return Source(
            f"REAL HIRO trials at 5x ({hiro})", ros.TARGET_RATE_HZ / ros.SOURCE_RATE_HZ, real
        )

    config = load_sim_config()
    sims = [
        simulate_trial(config, 1000 + k, "two-arm", rate_hz=ros.SOURCE_RATE_HZ)
        for k in range(SIM_TRIALS)
    ]
    return Source(
        "simulator, two-arm trials, 200 Hz at 5x",
        ros.TARGET_RATE_HZ / ros.SOURCE_RATE_HZ,
        lambda i: sims[i % SIM_TRIALS],
    )


@dataclass
class Playback:
    """One trial ready to publish: per sample its due offset (s), raw wrench per arm, events."""

    name: str
    offsets: np.ndarray
    raws: list[list[bytes]]
    """raws[i]: the wrench messages of sample i, in ARMS order"""
    events: dict[int, list[str]]
    """sample index -> /task_phase names published right after it"""
    last_stamp_ns: int


def playback(trial: Trial, base_ns: int, rate: float) -> Playback:
    """Trial re-stamped to start at `base_ns`; events placed as write_trial_bag places them."""

    t_ns = np.rint((np.asarray(trial.time, dtype=np.float64) - trial.time[0]) * 1e9).astype(
        np.int64
    )
    stamps = base_ns + t_ns
    wrench = [trial.wrench[arm].tolist() for arm in ARMS]
    raws = [
        [encode_wrench(int(s), arm, wrench[a][i]) for a, arm in enumerate(ARMS)]
        for i, s in enumerate(stamps.tolist())
    ]
    # an event follows the last sample before it (a sample at its exact time comes first)
    events: dict[int, list[str]] = {}
    for when, name in trial_phase_events(trial):
        e_ns = round((when - float(trial.time[0])) * 1e9)
        i = max(int(np.searchsorted(t_ns, e_ns, side="right")) - 1, 0)
        events.setdefault(i, []).append(name)
    return Playback(trial.name, t_ns / 1e9 / rate, raws, events, int(stamps[-1]))


# --- the publisher -------------------------------------------------------------------------


@dataclass
class PublisherStats:
    """What the publisher thread did (read by the main thread)."""

    published: dict[str, int] = field(default_factory=lambda: dict.fromkeys(ARMS, 0))
    """per arm, samples of the trials finished so far"""
    in_trial: int = 0
    """samples per arm published of the trial under way"""
    subtask_events: int = 0
    end_events: int = 0
    trials: list[dict[str, Any]] = field(default_factory=list)
    """per trial: index, name, start/end wall ns, samples, sub-task events, cut"""
    play_s: float = 0.0
    late: int = 0
    max_late_ms: float = 0.0
    error: str | None = None
    done: bool = False


class SoakPublisher(threading.Thread):
    """Publishes trial after trial until `deadline` (a cut trial still gets its end event)."""

    def __init__(self, node: Any, qos: Any, source: Source, seconds: float) -> None:
        super().__init__(name="soak-publisher", daemon=True)

        self.source = source
        self.seconds = seconds
        self.wrench_pubs = [
            node.create_publisher(WrenchStamped, wrench_topic(arm, ARMS), qos) for arm in ARMS
        ]
        self.phase_pub = node.create_publisher(String, PHASE_TOPIC, qos)
        self.stats = PublisherStats()
        self.stop_event = threading.Event()

    def matched(self) -> bool:
        """Every input topic of the segmenter has a subscriber."""
        return all(p.get_subscription_count() > 0 for p in (*self.wrench_pubs, self.phase_pub))

    def run(self) -> None:

        stats = self.stats
        deadline = time.perf_counter() + self.seconds
        base_ns = time.time_ns()
        i = 0
        try:
            while not self.stop_event.is_set() and time.perf_counter() < deadline:
                pb = playback(self.source.trial(i), base_ns, self.source.rate)
                base_ns = pb.last_stamp_ns + int(TRIAL_GAP_S * self.source.rate * 1e9)
                record = self._play(i, pb, deadline)
                if record["samples_per_arm"] == 0:
                    break  # cut before its first sample: there is no stream to end
                if record["cut"]:  # the end event the cut left out
                    self.phase_pub.publish(String(data=END_PHASE))
                stats.end_events += 1
                stats.trials.append(record)
                i += 1
                if time.perf_counter() < deadline:
                    self.stop_event.wait(TRIAL_GAP_S)
        except Exception as exc:  # reported in the results, never a silent end
            stats.error = f"{type(exc).__name__}: {exc}"
        finally:
            stats.done = True

    def _play(self, index: int, pb: Playback, deadline: float) -> dict[str, Any]:
        """Publish one trial at its recorded spacing / rate; stop early at `deadline`."""
        stats = self.stats
        pubs = self.wrench_pubs
        stop = self.stop_event
        perf = time.perf_counter
        t0 = perf()
        start_wall = time.time_ns()
        subtasks = 0
        n = 0
        cut = False
        for i, offset in enumerate(pb.offsets.tolist()):
            now = perf()
            if now >= deadline or stop.is_set():
                cut = True
                break
            delay = t0 + offset - now
            if delay > 0:
                time.sleep(delay)
            elif -delay * 1e3 > LATE_MS:
                stats.late += 1
                stats.max_late_ms = max(stats.max_late_ms, -delay * 1e3)
            for pub, raw in zip(pubs, pb.raws[i], strict=True):
                pub.publish(raw)
            n += 1
            stats.in_trial = n
            for name in pb.events.get(i, ()):
                self.phase_pub.publish(String(data=name))
                if name != END_PHASE:
                    subtasks += 1
        play_s = perf() - t0
        for arm in ARMS:
            stats.published[arm] += n
        stats.in_trial = 0
        stats.subtask_events += subtasks
        stats.play_s += play_s
        return {
            "index": index,
            "name": pb.name,
            "start_wall_ns": start_wall,
            "end_wall_ns": time.time_ns(),
            "samples_per_arm": n,
            "subtask_events": subtasks,
            "cut": cut,
        }


# --- the observer --------------------------------------------------------------------------


class SoakObserver:
    """Counts what the nodes publish: segmenter counters, applied events, beliefs and verdicts.

    Beliefs are binned by their header stamp (the classifier's wall clock when it computed them)
    against `split_ns`, the moment the first classifier exited: bin 0 before, bin 1 after.
    """

    def __init__(self, node: Any, qos: Any) -> None:

        seg, cls_cfg = SegmenterConfig(), ClassifierConfig()
        self.lock = threading.Lock()
        self.accepted = dict.fromkeys(ARMS, 0)
        self.rejected = dict.fromkeys(ARMS, 0)
        self.streams_ended = dict.fromkeys(ARMS, 0)
        self.applied = {"subtask": 0, "end": 0}
        self.beliefs = [0, 0]
        self.verdicts = [0, 0]
        self.split_ns: int | None = None
        self.word_topics = word_topics(seg.words_namespace, ARMS)
        self.applied_topic = seg.applied_phase_topic
        self.belief_sub = node.create_subscription(
            BeliefMsg, cls_cfg.belief_topic, self.on_belief, qos
        )
        self.subs = [self.belief_sub]
        # every word topic, so that the segmenter's own count of matched word readers (its
        # /diagnostics) reaches 2 only once the classifier's are matched too
        for (arm, level), topic in self.word_topics.items():
            on_words = functools.partial(self.on_words, arm, level == "primitives")
            self.subs.append(node.create_subscription(WordsMsg, topic, on_words, qos))
        self.subs.append(node.create_subscription(PhaseMsg, self.applied_topic, self.on_phase, qos))
        self.diagnostics = DiagnosticWatch(node)

    def on_belief(self, msg: Any) -> None:
        stamp = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
        with self.lock:
            b = 0 if self.split_ns is None or stamp < self.split_ns else 1
            self.beliefs[b] += 1
            if msg.final:
                self.verdicts[b] += 1

    def on_words(self, arm: str, counted: bool, msg: Any) -> None:
        if not counted:
            return  # the same counters come on the primitives topic
        with self.lock:
            self.accepted[arm] = max(self.accepted[arm], int(msg.samples_accepted))
            self.rejected[arm] = max(self.rejected[arm], int(msg.samples_rejected))
            if msg.end_of_stream:
                self.streams_ended[arm] += 1

    def on_phase(self, msg: Any) -> None:
        with self.lock:
            self.applied["end" if msg.name == END_PHASE else "subtask"] += 1

    def connected(self, node: Any) -> bool:
        """The nodes publish what this observes, the segmenter's writers matched both the
        classifier's readers and this observer's (the graph lists readers before that), and its
        readers matched the traffic's writers."""
        if not all(s.get_publisher_count() > 0 for s in self.subs):
            return False
        topics = [*self.word_topics.values(), self.applied_topic]
        return (
            all(node.count_subscribers("/" + t) >= 2 for t in topics)
            and self.diagnostics.segmenter_matched() >= 2
            and self.diagnostics.intake_matched()
        )


# --- processes -----------------------------------------------------------------------------

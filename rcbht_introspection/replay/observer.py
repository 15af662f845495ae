"""The harness's ears on the graph: records the nodes' outputs into Observations (rclpy).

Callbacks only keep the raw CDR and the receive time; decoding waits for `convert`, between
bags, so the observer's CPU during playback is small and the nodes under test keep theirs.
"""

from __future__ import annotations

import math
import threading
import time
from functools import partial
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rcbht_interfaces.msg import Belief as BeliefMsg
from rcbht_interfaces.msg import Phase as PhaseMsg
from rcbht_interfaces.msg import Verdict as VerdictMsg
from rcbht_interfaces.msg import Words as WordsMsg
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.serialization import deserialize_message
from std_msgs.msg import String

from rcbht_introspection.configure.params import (
    ClassifierConfig,
    SegmenterConfig,
    VerifierConfig,
    word_topics,
)
from rcbht_introspection.live.belief import UNKNOWN
from rcbht_introspection.messages import belief_from_msg, msg_to_word, to_ns
from rcbht_introspection.replay.scoring import (
    AppliedPhase,
    Observations,
    ReceivedBelief,
)
from rcbht_introspection.replay.verify_scoring import VerdictRecord


class DiagnosticWatch:
    """The latest value of each key of each /diagnostics status, by status name: what a harness
    waits on before it plays (the graph's counts show a match on one side only)."""

    def __init__(self, node: Node) -> None:
        self.latest: dict[str, dict[str, str]] = {}
        node.create_subscription(DiagnosticArray, "/diagnostics", self.on_status, 10)

    def on_status(self, msg: Any) -> None:
        for status in msg.status:
            self.latest[status.name] = {kv.key: kv.value for kv in status.values}

    def count(self, status: str, key: str) -> int:
        """The integer `key` of `status` last reported (0 before it was)."""
        return int(self.latest.get(status, {}).get(key, 0))

    def forget(self, status: str) -> None:
        """Drop the last `status` (its node stopped): a successor's must arrive before `count`
        reports it again."""
        self.latest.pop(status, None)

    def segmenter_matched(self) -> int:
        """Subscribers the segmenter's writers matched on every word topic and on its applied
        events."""
        keys = ("word subscribers matched", "phase subscribers matched")
        return min(self.count("segmenter_node: outputs", key) for key in keys)

    def classifier_matched(self) -> bool:
        """The classifier's readers matched a publisher on every input (its words and events):
        what a writer sends before the reader's side matched waits for a retransmission."""
        return self.count("classifier_node: belief", "input publishers matched") >= 1

    def intake_matched(self) -> bool:
        """The segmenter's readers matched a publisher on every input."""
        return self.count("segmenter_node: outputs", "intake publishers matched") >= 1

    def verifier_matched(self) -> bool:
        """The verifier's readers matched a publisher on every input and its verdict writer
        matched a reader."""
        values = ("intake publishers matched", "verdict subscribers matched")
        return all(self.count("verifier_node: verifier", key) >= 1 for key in values)


class Observer:
    """Subscribes the nodes' outputs (state, beliefs, applied events, words) in this process."""

    def __init__(
        self, node: Node, seg: SegmenterConfig, cls_cfg: ClassifierConfig, qos: QoSProfile
    ) -> None:
        self.obs = Observations()
        self.lock = threading.Lock()
        self.received: list[tuple[int, str, tuple[str, str], bytes]] = []
        """(wall ns, kind, (arm, level) of words, raw CDR) not yet decoded"""
        self.last_state_sent = 0
        """Source timestamp (the classifier's clock) of the latest /task_state message."""
        self.republished = cls_cfg.publish_rate_hz > 0
        """The classifier republishes /task_state on a timer (not only on change)."""
        self.types = {"state": String, "belief": BeliefMsg, "phase": PhaseMsg, "words": WordsMsg}
        self.subs = [
            node.create_subscription(
                self.types[kind],
                topic,
                # (raw, MessageInfo): rclpy passes the info to two-argument callbacks
                partial(self.on_message, kind, ("", "")),
                qos,
                raw=True,
            )
            for kind, topic in (
                ("state", cls_cfg.state_topic),
                ("belief", cls_cfg.belief_topic),
                ("phase", seg.applied_phase_topic),
            )
        ]
        self.word_topics = word_topics(seg.words_namespace, seg.arms)
        for key, topic in self.word_topics.items():
            self.subs.append(
                node.create_subscription(
                    WordsMsg,
                    topic,
                    partial(self.on_message, "words", key),
                    qos,
                    raw=True,
                )
            )

    def on_message(self, kind: str, key: tuple[str, str], raw: bytes, info: Any) -> None:
        """Keep one message's raw CDR and receive time (executor thread)."""
        wall = time.time_ns()
        with self.lock:
            self.received.append((wall, kind, key, raw))
            if kind == "state":
                self.last_state_sent = int(info.get("source_timestamp") or 0)

    def state_settled(self, since_ns: int) -> bool:
        """A /task_state message published after `since_ns` (the classifier's clock) arrived:
        the topic delivers in order, so every change published before it is in (without the
        republishing timer there is no such message to wait for)."""
        with self.lock:
            return not self.republished or self.last_state_sent > since_ns

    def convert(self) -> None:
        """Decode what arrived since the last call into the observations."""
        with self.lock:
            received, self.received = self.received, []
        for wall, kind, (arm, level), raw in received:
            msg = deserialize_message(raw, self.types[kind])
            with self.lock:
                obs = self.obs
                if kind == "state":
                    # a change from the last state seen, or from the classifier's first state
                    # ('unknown'): its republishing before the first change is no change
                    if (obs.states[-1][1] if obs.states else UNKNOWN) != msg.data:
                        obs.states.append((wall, msg.data))
                elif kind == "belief":
                    obs.beliefs.append(
                        ReceivedBelief(
                            wall,
                            belief_from_msg(msg),
                            to_ns(msg.trigger_stamp),
                            to_ns(msg.header.stamp),
                        )
                    )
                elif kind == "phase":
                    obs.phases.append(
                        AppliedPhase(
                            wall, msg.name, msg.time, msg.stream_id, to_ns(msg.header.stamp)
                        )
                    )
                else:
                    sid = msg.stream_id
                    obs.words.setdefault((sid, arm, level), []).extend(
                        msg_to_word(w) for w in msg.words
                    )
                    if msg.words:
                        stamp = to_ns(msg.header.stamp)
                        obs.triggers.setdefault(sid, set()).add(stamp)
                        obs.word_arrivals.append((wall, stamp))
                    if msg.end_of_stream:
                        obs.ends[(sid, arm, level)] = (
                            int(msg.samples_accepted),
                            int(msg.samples_rejected),
                        )

    def ended(self, stream_id: int, arms: tuple[str, ...]) -> bool:
        """Every word topic has ended stream `stream_id` (decodes what arrived first)."""
        self.convert()
        with self.lock:
            return self.obs.ended(stream_id, arms)

    def finals_since(self, index: int) -> list[ReceivedBelief]:
        """The verdicts from belief `index` on (decodes what arrived first)."""
        self.convert()
        with self.lock:
            return self.obs.finals_since(index)


def _furthest_signal(msg: Any) -> str:
    """The Verdict's signal furthest over its threshold ('' without signals)."""
    best, out = -math.inf, ""
    for name, score, threshold in zip(
        msg.signals, msg.signal_scores, msg.signal_thresholds, strict=False
    ):
        ratio = score / threshold if threshold else math.inf
        if ratio > best:  # NaN never is
            best, out = ratio, name
    return out


class VerdictObserver:
    """Subscribes verifier_node's verdicts and health; one VerdictRecord per stream.

    Health values are told apart by stream with the DDS source timestamps (the node's clock):
    a stream's values are those published after its first verdict."""

    def __init__(self, node: Node, cfg: VerifierConfig, qos: QoSProfile) -> None:
        self.lock = threading.Lock()
        self.records: dict[int, VerdictRecord] = {}
        self.first_sent: dict[int, int] = {}
        """stream id -> source timestamp of its first verdict"""
        self.last_health: dict[int, str] = {}
        """stream id -> health carried by its latest verdict"""
        self.health: list[tuple[int, str]] = []
        """(source ns, value) of each /task_health message"""
        latched = QoSProfile(depth=1, reliability=qos.reliability)  # type: ignore[no-untyped-call]  # rclpy's QoSProfile takes **kwargs
        latched.durability = DurabilityPolicy.TRANSIENT_LOCAL
        self.subs = [
            # (msg, MessageInfo) callbacks, which rclpy passes to two-argument callables
            node.create_subscription(VerdictMsg, cfg.verdict_topic, self.on_verdict, qos),  # type: ignore[arg-type]
            node.create_subscription(String, cfg.health_topic, self.on_health, latched),  # type: ignore[arg-type]
        ]

    def on_verdict(self, msg: Any, info: dict[str, int]) -> None:
        """One Verdict (executor thread): at most one per step_s of stream time."""
        alarm = None if math.isnan(msg.alarm_time) else float(msg.alarm_time)
        onset = None if math.isnan(msg.onset) else float(msg.onset)
        wall = time.time_ns()
        with self.lock:
            rec = self.records.setdefault(msg.stream_id, VerdictRecord(msg.stream_id))
            self.first_sent.setdefault(msg.stream_id, int(info.get("source_timestamp") or 0))
            self.last_health[msg.stream_id] = msg.health
            rec.arrivals.append((wall, to_ns(msg.header.stamp)))
            rec.add(
                msg.time,
                msg.score,
                alarm,
                onset,
                msg.failure_class,
                dict(zip(msg.direction_axes, msg.directions, strict=False)),
                msg.health,
                _furthest_signal(msg),
            )

    def on_health(self, msg: String, info: dict[str, int]) -> None:
        """One /task_health value (executor thread), stamped with its source timestamp."""
        with self.lock:
            self.health.append((int(info.get("source_timestamp") or time.time_ns()), msg.data))

    def reached(self, stream_id: int, end_time: float) -> bool:
        """The verdict of stream `stream_id` at `end_time` (its last sample) arrived, and the
        health topic shows what that verdict says."""
        with self.lock:
            rec = self.records.get(stream_id)
            return (
                rec is not None
                and rec.end_time >= end_time - 1e-6
                and bool(self.health)
                and self.health[-1][1] == self.last_health[stream_id]
            )

    def record(self, stream_id: int) -> VerdictRecord:
        """The stream's record, with the health values published during it."""
        with self.lock:
            rec = self.records.get(stream_id, VerdictRecord(stream_id))
            since = self.first_sent.get(stream_id)
            rec.health_seen = []
            for sent, value in self.health:
                if since is not None and sent >= since and rec.health_seen[-1:] != [value]:
                    rec.health_seen.append(value)
            return rec

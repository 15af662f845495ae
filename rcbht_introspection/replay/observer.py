"""The harness's ears on the graph: records the nodes' outputs into Observations (rclpy).

Callbacks only keep the raw CDR and the receive time; decoding waits for `convert`, between
bags, so the observer's CPU during playback is small and the nodes under test keep theirs.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from functools import partial
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rcbht_interfaces.msg import Belief as BeliefMsg
from rcbht_interfaces.msg import Phase as PhaseMsg
from rcbht_interfaces.msg import Words as WordsMsg
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
from std_msgs.msg import String

from rcbht_introspection.nodes.conversions import belief_from_msg, msg_to_word, to_ns
from rcbht_introspection.nodes.params import ClassifierConfig, SegmenterConfig, word_topics
from rcbht_introspection.replay.scoring import (
    AppliedPhase,
    Observations,
    ReceivedBelief,
)


def segmenter_matches(node: Node) -> Callable[[], int]:
    """A function giving the subscribers the segmenter's writers matched on every word topic."""
    latest = [0]

    def on_status(msg: Any) -> None:
        for status in msg.status:
            if status.name == "segmenter_node: outputs":
                values = {kv.key: kv.value for kv in status.values}
                latest[0] = int(values.get("word subscribers matched", 0))

    node.create_subscription(DiagnosticArray, "/diagnostics", on_status, 10)
    return lambda: latest[0]


class Observer:
    """Subscribes the nodes' outputs (state, beliefs, applied events, words) in this process."""

    def __init__(
        self, node: Node, seg: SegmenterConfig, cls_cfg: ClassifierConfig, qos: QoSProfile
    ) -> None:
        self.obs = Observations()
        self.lock = threading.Lock()
        self.received: list[tuple[int, str, tuple[str, str], bytes]] = []
        """(wall ns, kind, (arm, level) of words, raw CDR) not yet decoded"""
        self.types = {"state": String, "belief": BeliefMsg, "phase": PhaseMsg, "words": WordsMsg}
        self.subs = [
            node.create_subscription(
                self.types[kind], topic, partial(self.on_message, kind, ("", "")), qos, raw=True
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
                    WordsMsg, topic, partial(self.on_message, "words", key), qos, raw=True
                )
            )

    def on_message(self, kind: str, key: tuple[str, str], raw: bytes) -> None:
        """Keep one message's raw CDR and receive time (executor thread)."""
        wall = time.time_ns()
        with self.lock:
            self.received.append((wall, kind, key, raw))

    def convert(self) -> None:
        """Decode what arrived since the last call into the observations."""
        with self.lock:
            received, self.received = self.received, []
        for wall, kind, (arm, level), raw in received:
            msg = deserialize_message(raw, self.types[kind])
            with self.lock:
                obs = self.obs
                if kind == "state":
                    if not obs.states or obs.states[-1][1] != msg.data:
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

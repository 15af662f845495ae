"""segmenter_node: WrenchStamped per arm -> RCBHT words on rcbht/{primitives,compositions,behaviors}.

Parameters: see config/segmenter.yaml (`ros2 param describe` shows each description). /task_phase
events are placed on the stream clock, applied as sub-task boundaries and republished as
rcbht_interfaces/Phase; an end event ("done") finishes the streams. Malformed samples are
dropped and counted (Words.samples_rejected).
"""

from __future__ import annotations

import sys
from functools import partial

from geometry_msgs.msg import WrenchStamped
from rcbht_interfaces.msg import Phase as PhaseMsg
from rcbht_interfaces.msg import Words as WordsMsg
from rclpy.node import Node
from std_msgs.msg import String

from rcbht_introspection.live.segmenter import Output, SegmenterSession, arm_stream_factory
from rcbht_introspection.nodes.common import declare_config, qos_profile, run
from rcbht_introspection.nodes.conversions import phase_msg, words_msg, wrench_sample
from rcbht_introspection.nodes.params import SegmenterConfig, word_topics
from rcbht_introspection.taxonomy.words import LEVELS


class SegmenterNode(Node):
    """Thin adapter: messages in -> SegmenterSession -> Words / Phase messages out."""

    def __init__(self) -> None:
        super().__init__("segmenter_node")
        self.cfg = declare_config(self, SegmenterConfig)
        cfg = self.cfg
        factory = arm_stream_factory(
            cfg.taxonomy_profile, cfg.taxonomy_config_file, cfg.stream_config_file
        )
        self.session = SegmenterSession(cfg.arms, factory, cfg.end_phases)
        qos = qos_profile(cfg.qos_depth, cfg.qos_reliability)
        topics = word_topics(cfg.words_namespace, cfg.arms)
        self.word_pubs = {
            (arm, level): self.create_publisher(WordsMsg, topics[(arm, level.value + "s")], qos)
            for arm in cfg.arms
            for level in LEVELS
        }
        self.phase_pub = self.create_publisher(PhaseMsg, cfg.applied_phase_topic, qos)
        for arm, topic in zip(cfg.arms, cfg.wrench_topics, strict=True):
            self.create_subscription(WrenchStamped, topic, partial(self.on_wrench, arm), qos)
        self.create_subscription(String, cfg.phase_topic, self.on_phase, qos)
        self.get_logger().info(
            f"arms {list(cfg.arms)} from {list(cfg.wrench_topics)}, events on {cfg.phase_topic}, "
            f"profile {cfg.taxonomy_profile}"
        )

    def on_wrench(self, arm: str, msg: WrenchStamped) -> None:
        stamp, wrench = wrench_sample(msg)
        out = self.session.push(arm, stamp, wrench)
        if out.rejected:
            self.get_logger().warning(
                f"dropped a wrench sample of arm {arm}: {out.rejected} "
                f"(rejected so far: {self.session.counts[arm].rejected})",
                throttle_duration_sec=1.0,
            )
            return
        if out.words:
            self.publish(out, stamp, self.session.origin_ns or 0)

    def on_phase(self, msg: String) -> None:
        out = self.session.phase(msg.data)
        event = out.phase
        assert event is not None
        if not event.known:
            self.get_logger().warning(
                f"ignored unknown /task_phase name {event.name!r} (known: sub-task names and "
                f"{list(self.cfg.end_phases)})"
            )
            return
        self.publish(out, event.stamp_ns, event.origin_ns or 0)
        self.phase_pub.publish(phase_msg(event))

    def publish(self, out: Output, stamp_ns: int, origin_ns: int) -> None:
        """One Words message per arm and level that has new words (every level at stream end)."""
        for arm in self.cfg.arms:
            words = out.words.get(arm, [])
            counts = self.session.counts[arm]
            for level in LEVELS:
                batch = [w for w in words if w.level == level]
                if not batch and not out.ended:
                    continue
                self.word_pubs[(arm, level)].publish(
                    words_msg(
                        arm,
                        level,
                        batch,
                        stamp_ns,
                        origin_ns,
                        end_of_stream=out.ended,
                        accepted=counts.accepted,
                        rejected=counts.rejected_total,
                    )
                )


def main(args: list[str] | None = None) -> int:
    """Entry point (`ros2 run rcbht_introspection segmenter_node`)."""
    return run(SegmenterNode, "segmenter_node", args)


if __name__ == "__main__":
    sys.exit(main())

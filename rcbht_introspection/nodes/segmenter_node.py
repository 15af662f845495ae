"""segmenter_node: WrenchStamped per arm -> RCBHT words on rcbht/{primitives,compositions,behaviors}.

Parameters: config/segmenter.yaml (`ros2 param describe` shows each). /task_phase events are
placed on the stream clock, applied as sub-task boundaries and republished as rcbht_interfaces/
Phase; an end event ("done") finishes the streams. The session (live/segmenter.py) checks,
counts and drops bad samples and runs the sensor intake; this node subscribes, publishes in
the order of live/publication.py and serves `~/tare`.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from functools import partial

from diagnostic_msgs.srv import SelfTest
from geometry_msgs.msg import PoseStamped
from rcbht_interfaces.msg import Phase as PhaseMsg
from rcbht_interfaces.msg import Words as WordsMsg
from rclpy.event_handler import PublisherEventCallbacks

from rcbht_introspection.configure.params import SegmenterConfig, word_topics
from rcbht_introspection.configure.sessions import segmenter_session
from rcbht_introspection.lifetime import StopSignal
from rcbht_introspection.live.health import ArmHealth, CounterWatch, Health, outputs_health
from rcbht_introspection.live.health import segmenter_health as session_health
from rcbht_introspection.live.join import Watermarks
from rcbht_introspection.live.publication import WordsOut, idle_marks, publication
from rcbht_introspection.live.segmenter import Output, PhaseEvent
from rcbht_introspection.messages import phase_msg, self_test_status, words_out_msg
from rcbht_introspection.nodes.common import ManagedNode, phase_qos, qos_profile, run
from rcbht_introspection.nodes.intake import Intake
from rcbht_introspection.taxonomy.config import taxonomy_digest
from rcbht_introspection.taxonomy.words import LEVELS


class SegmenterNode(ManagedNode):
    """Thin adapter: messages in -> SegmenterSession -> Words / Phase messages out."""

    def __init__(self) -> None:
        super().__init__("segmenter_node", SegmenterConfig)
        self.create_service(SelfTest, "~/tare", self.on_tare)  # Trigger's request, a status

    def configure(self, cfg: SegmenterConfig) -> None:
        self.cfg = cfg
        self.session, taxonomy = segmenter_session(cfg)
        self.about = f"profile {taxonomy.profile} (sha256 {taxonomy_digest(taxonomy)[:12]})"
        self.arm_health = {arm: ArmHealth(arm) for arm in cfg.arms}
        self.marks, self.event_watch = Watermarks(), CounterWatch()
        self.qos = qos_profile(cfg.qos_depth, cfg.qos_reliability)
        topics = word_topics(cfg.words_namespace, cfg.arms)
        # no QoS-event handlers on the outputs: each is a waitable in every wake-up's wait set
        quiet = PublisherEventCallbacks(use_default_callbacks=False)
        self.word_pubs = {
            (arm, level): self.create_publisher(
                WordsMsg, topics[(arm, level.value + "s")], self.qos, event_callbacks=quiet
            )
            for arm in cfg.arms
            for level in LEVELS
        }
        latched = phase_qos(cfg.qos_reliability)
        self.phase_pub = self.create_publisher(
            PhaseMsg, cfg.applied_phase_topic, latched, event_callbacks=quiet
        )
        self.cpu_at_start = time.process_time()

    def activate(self) -> None:
        cfg = self.cfg
        self.inputs = Intake(self, cfg, (self.sample, self.on_phase, self.on_tick), self.qos)
        # the latest pose is what counts: depth 1 (none, or one topic per arm)
        for arm, topic in zip(cfg.arms, cfg.pose_topics, strict=False):
            pose = partial(self.on_pose, arm)
            self.create_subscription(PoseStamped, topic, pose, qos_profile(1, cfg.qos_reliability))
        self.get_logger().info(
            f"arms {list(cfg.arms)} from {list(cfg.wrench_topics)}, events on {cfg.phase_topic}, "
            f"{self.about}, stream {cfg.stream_profile}"
        )

    def deactivate(self) -> None:
        cpu = time.process_time() - self.cpu_at_start
        self.get_logger().info(f"{self.session.statistics()}, CPU {cpu:.2f} s after start-up")

    def sample(self, arm: str, stamp: int, wrench: Sequence[float], source_ns: int | None) -> None:
        out = self.session.push(arm, stamp, wrench, source_ns)
        if out.batches or out.phases:
            self.publish(out)
        if out.rejected:
            self.get_logger().warning(
                f"dropped a wrench sample of arm {arm}: {out.rejected} "
                f"(rejected so far: {self.session.counts[arm].rejected})",
                throttle_duration_sec=1.0,
            )

    def on_pose(self, arm: str, msg: PoseStamped) -> None:
        """The sensor's latest orientation in the world, for the gravity compensation."""
        q = msg.pose.orientation
        if problem := self.session.pose_quaternion(arm, q.x, q.y, q.z, q.w):
            log = self.get_logger()
            log.warning(f"ignored a pose of arm {arm}: {problem}", throttle_duration_sec=1.0)

    def on_tare(self, request: SelfTest.Request, response: SelfTest.Response) -> SelfTest.Response:
        """~/tare: measure each arm's tare over its next intake.tare_window_s seconds."""
        taken = self.state_label == "active"
        message = f"not active ({self.state_label}): no tare"
        if taken:
            self.session.tare()
            window = self.cfg.intake.tare_window_s
            message = f"tare of arms {list(self.cfg.arms)} over the next {window} s of samples"
            self.get_logger().info(message)
        self_test_status(response, f"{self.get_name()}: tare", taken, message)
        return response

    def on_phase(self, name: str, source_ns: int | None) -> None:
        out = self.session.phase(name, source_ns)
        if out.unknown_phase is not None:
            self.get_logger().warning(
                f"ignored unknown /task_phase name {out.unknown_phase!r} (known: sub-task names "
                f"and {list(self.cfg.end_phases)})"
            )
        self.publish(out)

    def on_tick(self, idle: bool) -> None:
        """Apply events that waited longer than the hold time for a later sample, while no
        samples arrive (a backlog published before the event goes first); mark idle levels."""
        if self.session.pending and idle:
            self.publish(self.session.flush(time.time_ns()))
        for item in idle_marks(self.session, self.marks, time.monotonic()):
            self.publish_words(item)

    def publish(self, out: Output) -> None:
        """The batches' Words messages and the applied events, in live/publication.py's order."""
        for batch in out.batches:
            self.arm_health[batch.arm].words(batch.stream_id, batch.words)
        for item in publication(out, self.marks, time.monotonic()):
            if isinstance(item, PhaseEvent):
                self.phase_pub.publish(phase_msg(item))
            else:
                self.publish_words(item)

    def publish_words(self, item: WordsOut) -> None:
        msg = words_out_msg(item, self.session.counts[item.batch.arm])
        self.word_pubs[(item.batch.arm, item.message.level)].publish(msg)

    def health(self, period_s: float) -> list[Health]:
        """Per arm intake, the events (live/health.py), then the outputs' matched peers."""
        active = self.state_label == "active"
        out = session_health(self.session, self.arm_health, period_s, active, self.event_watch)
        words = min(p.get_subscription_count() for p in self.word_pubs.values())
        matched = self.inputs.publishers() if self.inputs is not None else 0
        phases = self.phase_pub.get_subscription_count()
        return [*out, outputs_health(self.get_name(), words, phases, matched)]


def main(args: list[str] | None = None, stop: StopSignal | None = None) -> int:
    """Entry point (`ros2 run rcbht_introspection segmenter_node`)."""
    return run(SegmenterNode, "segmenter_node", args, stop or StopSignal.install(until_up=True))


if __name__ == "__main__":
    sys.exit(main())

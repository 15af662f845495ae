"""segmenter_node: WrenchStamped per arm -> RCBHT words on rcbht/{primitives,compositions,behaviors}.

Parameters: see config/segmenter.yaml (`ros2 param describe` shows each description). /task_phase
events are placed on the stream clock, applied as sub-task boundaries and republished as
rcbht_interfaces/Phase; an end event ("done") finishes the streams. Malformed samples are
dropped and counted (Words.samples_rejected). The sensor intake (parameters intake.*, live/intake.py)
runs in the session; this node only subscribes the sensor poses and serves `~/tare`.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable, Sequence
from functools import partial

from diagnostic_msgs.msg import DiagnosticStatus
from diagnostic_msgs.srv import SelfTest
from geometry_msgs.msg import PoseStamped
from rcbht_interfaces.msg import Phase as PhaseMsg
from rcbht_interfaces.msg import Words as WordsMsg
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.publisher import Publisher
from rclpy.subscription import Subscription

from rcbht_introspection.live.gravity import rotation_from_quaternion
from rcbht_introspection.live.health import (
    OK,
    WARN,
    ArmHealth,
    CounterWatch,
    Health,
    segmenter_health,
)
from rcbht_introspection.live.join import Watermarks
from rcbht_introspection.live.publication import publication
from rcbht_introspection.live.segmenter import (
    Output,
    PhaseEvent,
    SegmenterSession,
    arm_stream_factory,
)
from rcbht_introspection.nodes.common import ManagedNode, phase_qos, qos_profile, run
from rcbht_introspection.nodes.conversions import phase_msg, words_msg
from rcbht_introspection.nodes.intake import Intake
from rcbht_introspection.nodes.lifetime import StopSignal
from rcbht_introspection.nodes.params import SegmenterConfig, segmenter_taxonomy, word_topics
from rcbht_introspection.task import load_task_file
from rcbht_introspection.taxonomy.config import taxonomy_digest
from rcbht_introspection.taxonomy.words import LEVELS

TARE_SERVICE = "~/tare"
"""Re-tare at the next samples. Type diagnostic_msgs/srv/SelfTest: std_srvs (Trigger) is not among
the pinned PyPI ROS wheels; SelfTest has Trigger's empty request, and its response says whether
the request was taken (`passed`) and why, in one DiagnosticStatus message."""


class SegmenterNode(ManagedNode):
    """Thin adapter: messages in -> SegmenterSession -> Words / Phase messages out."""

    def __init__(self) -> None:
        super().__init__("segmenter_node", SegmenterConfig)
        self.pose_subs: list[Subscription] = []
        self.bad_poses = 0
        self.create_service(SelfTest, TARE_SERVICE, self.on_tare)

    def configure(self, cfg: SegmenterConfig) -> None:
        self.cfg = cfg
        taxonomy = segmenter_taxonomy(cfg)
        self.taxonomy_profile = taxonomy.profile
        self.taxonomy_sha256 = taxonomy_digest(taxonomy)
        factory = arm_stream_factory(
            stream_file=cfg.stream_config_file, stream_profile=cfg.stream_profile, taxonomy=taxonomy
        )
        self.last_sample = time.monotonic()
        task = load_task_file(cfg.task_file) if cfg.task_file else None
        self.session = SegmenterSession(
            cfg.arms,
            factory,
            tuple(dict.fromkeys([*cfg.end_phases, *(task.end_phases if task else ())])),
            task.subtasks if task else None,
            hold_s=cfg.event_hold_s,
            max_hold_s=cfg.event_max_hold_s,
            intake=cfg.intake,
        )
        self.arm_health = {arm: ArmHealth(arm) for arm in cfg.arms}
        self.marks = Watermarks()
        self.event_watch = CounterWatch()
        self.qos = qos_profile(cfg.qos_depth, cfg.qos_reliability)
        topics = word_topics(cfg.words_namespace, cfg.arms)
        # no default QoS-event handlers on the outputs: each is a waitable that the executor adds
        # to its wait set on every wake-up (1-2 kHz); the input subscriptions keep theirs
        quiet = PublisherEventCallbacks(use_default_callbacks=False)
        self.word_pubs = {
            (arm, level): self.create_publisher(
                WordsMsg, topics[(arm, level.value + "s")], self.qos, event_callbacks=quiet
            )
            for arm in cfg.arms
            for level in LEVELS
        }
        self.phase_pub = self.create_publisher(
            PhaseMsg, cfg.applied_phase_topic, phase_qos(cfg.qos_reliability), event_callbacks=quiet
        )
        self.cpu_at_start = time.process_time()
        self.inputs = None

    def activate(self) -> None:
        cfg = self.cfg
        self.inputs = Intake(
            self,
            self.subscribe,
            (cfg.arms, cfg.wrench_topics, cfg.phase_topic),
            (self.sample, self.on_phase),
            self.qos,
        )
        # the latest pose is what counts: depth 1, served by the executor (at least every 20 ms)
        self.pose_subs = [
            self.create_subscription(
                PoseStamped,
                topic,
                partial(self.on_pose, arm),
                qos_profile(1, cfg.qos_reliability),
            )
            for arm, topic in zip(cfg.arms, cfg.pose_topics, strict=False)  # none, or one per arm
        ]
        self.flush_timer = self.create_timer(min(cfg.event_hold_s / 4, 0.05), self.on_flush)
        self.get_logger().info(
            f"arms {list(cfg.arms)} from {list(cfg.wrench_topics)}, events on {cfg.phase_topic}, "
            f"profile {self.taxonomy_profile} (sha256 {self.taxonomy_sha256[:12]}), "
            f"stream {cfg.stream_profile}"
        )

    def deactivate(self) -> None:
        if self.inputs is not None:
            self.inputs.destroy()
        self.inputs = None
        for pose_sub in self.pose_subs:
            self.destroy_subscription(pose_sub)
        self.destroy_timer(self.flush_timer)
        self.pose_subs = []
        self.log_statistics()

    def cleanup(self) -> None:
        for pub in (*self.word_pubs.values(), self.phase_pub):
            self.destroy_publisher(pub)
        self.word_pubs = {}

    def sample(self, arm: str, stamp: int, wrench: Sequence[float], source_ns: int | None) -> None:
        self.last_sample = time.monotonic()
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
        try:
            rotation = rotation_from_quaternion(q.x, q.y, q.z, q.w)
        except ValueError as exc:  # a zero or non-finite quaternion
            self.bad_poses += 1
            self.get_logger().warning(
                f"ignored a pose of arm {arm}: {exc}", throttle_duration_sec=1.0
            )
            return
        self.session.pose(arm, rotation)  # subscribed only while active: the session exists

    def on_tare(self, request: SelfTest.Request, response: SelfTest.Response) -> SelfTest.Response:
        """~/tare: measure each arm's tare over its next intake.tare_window_s seconds."""
        response.id = f"{self.get_name()} tare"
        taken = self.state_label == "active"
        if not taken:
            message = f"not active ({self.state_label}): no tare"
        else:
            self.session.tare()
            message = (
                f"tare of arms {list(self.cfg.arms)} over the next "
                f"{self.cfg.intake.tare_window_s} s of samples"
            )
            self.get_logger().info(message)
        response.passed = bytes([taken])  # a `byte` field
        response.status = [
            DiagnosticStatus(
                level=bytes([OK if taken else WARN]),
                name=f"{self.get_name()}: tare",
                message=message,
            )
        ]
        return response

    def on_phase(self, name: str, source_ns: int | None) -> None:
        out = self.session.phase(name, source_ns)
        if out.unknown_phase is not None:
            self.get_logger().warning(
                f"ignored unknown /task_phase name {out.unknown_phase!r} (known: sub-task names "
                f"and {list(self.cfg.end_phases)})"
            )
        self.publish(out)

    def on_flush(self) -> None:
        """Apply sub-task events that waited longer than the hold time for a later sample.

        Only while no samples arrive: a backlog of samples published before the event must be
        consumed first (each later-published sample applies due events itself).
        """
        idle = time.monotonic() - self.last_sample > self.cfg.event_hold_s
        if self.session.pending and idle:
            self.publish(self.session.flush(time.time_ns()))
        self.publish_watermarks()

    def publish_watermarks(self) -> None:
        """Empty Words messages on levels that lag the arm's word numbers (live/join.Watermarks)."""
        now = time.monotonic()
        for arm, stream_id, level, seq_end in self.marks.due(now):
            if stream_id != self.session.stream_id or self.session.origin_ns is None:
                continue
            counts = self.session.counts[arm]
            self.word_pubs[(arm, level)].publish(
                words_msg(
                    arm,
                    level,
                    [],
                    self.session.state[arm].last_ns,
                    self.session.origin_ns,
                    stream_id=stream_id,
                    batch_size=0,
                    accepted=counts.accepted,
                    rejected=counts.rejected_total,
                    seq_end=seq_end,
                )
            )
            self.marks.published(arm, stream_id, level, seq_end, now)

    def log_statistics(self) -> None:
        """Log what the node did (samples, rejections, CPU time): its last line when it stops."""
        counts = {arm: (c.accepted, c.rejected_total) for arm, c in self.session.counts.items()}
        intake = {
            arm: (c.respaced, self.session.frozen[arm].episodes, self.session.tares[arm].completed)
            for arm, c in self.session.counts.items()
        }
        self.get_logger().info(
            f"samples (accepted, rejected) per arm {counts}, (respaced samples, frozen episodes, "
            f"tares) per arm {intake}, unknown events "
            f"{self.session.unknown_phases}, late events {self.session.late_phases}, "
            f"CPU {time.process_time() - self.cpu_at_start:.2f} s after start-up"
        )

    def publish(self, out: Output) -> None:
        """The Words messages of each batch and the applied events, in the order of
        live/publication.py (an event before the words of the samples after it)."""
        now = time.monotonic()
        for batch in out.batches:
            self.arm_health[batch.arm].words(batch.stream_id, batch.words)
        for item in publication(out, self.marks, now):
            if isinstance(item, PhaseEvent):
                self.phase_pub.publish(phase_msg(item))
                continue
            batch, message = item.batch, item.message
            counts = self.session.counts[batch.arm]
            self.word_pubs[(batch.arm, message.level)].publish(
                words_msg(
                    batch.arm,
                    message.level,
                    message.words,
                    batch.stamp_ns,
                    batch.origin_ns,
                    stream_id=batch.stream_id,
                    batch_size=item.batch_size,
                    end_of_stream=message.end_of_stream,
                    accepted=counts.accepted,
                    rejected=counts.rejected_total,
                    seq_end=message.seq_end,
                    wrench=item.wrench,
                )
            )

    def health(self, period_s: float) -> list[Health]:
        """Per arm intake, the events (live/health.py), then the outputs' matched peers."""
        out = segmenter_health(
            self.session,
            self.arm_health,
            period_s,
            active=self.state_label == "active",
            frozen_checks=bool(self.cfg.intake.frozen_samples),
            gravity=self.cfg.intake.compensates_gravity,
            bad_poses=self.bad_poses,
            watch=self.event_watch,
        )
        matched = self.inputs.publishers() if self.inputs is not None else 0
        out.append(outputs_health(self.word_pubs.values(), self.phase_pub, matched))
        return out


def outputs_health(word_pubs: Iterable[Publisher], phase_pub: Publisher, intake: int) -> Health:
    """Publishers matched to the inputs and subscribers to the outputs: a harness waits for
    them before it plays a bag."""
    matched = min(p.get_subscription_count() for p in word_pubs)
    values = (
        ("word subscribers matched", str(matched)),
        ("phase subscribers matched", str(phase_pub.get_subscription_count())),
        ("intake publishers matched", str(intake)),
    )
    return Health(
        "segmenter_node: outputs", OK, f"{matched} subscribers on every word topic", values
    )


def main(args: list[str] | None = None, stop: StopSignal | None = None) -> int:
    """Entry point (`ros2 run rcbht_introspection segmenter_node`)."""
    return run(SegmenterNode, "segmenter_node", args, stop or StopSignal.install(until_up=True))


if __name__ == "__main__":
    sys.exit(main())

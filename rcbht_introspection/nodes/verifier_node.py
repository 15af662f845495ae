"""verifier_node: WrenchStamped per arm + /task_phase -> rcbht/verdict and /task_health.

Parameters: see config/verifier.yaml. The samples and events are taken as segmenter_node takes
them (verify/stream.py: same checks, event placement and streams); the verifier model
(verify/) judges each tick. Without a usable model (missing, unreadable, other arms) it logs
why once, publishes no verdicts and keeps /task_health at "unknown". /task_health is published
when it changes and at `publish_rate_hz`, latched (a late subscriber gets the current value).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence

from rcbht_interfaces.msg import Belief as BeliefMsg
from rcbht_interfaces.msg import Verdict as VerdictMsg
from rclpy.qos import DurabilityPolicy
from std_msgs.msg import String

from rcbht_introspection.configure.params import VerifierConfig
from rcbht_introspection.configure.sessions import verifier_stream
from rcbht_introspection.lifetime import StopSignal
from rcbht_introspection.live.health import CounterWatch, Health, LatencyWindow, file_sha256
from rcbht_introspection.messages import belief_from_msg, verdict_msg
from rcbht_introspection.nodes.common import ManagedNode, qos_profile, run
from rcbht_introspection.nodes.intake import Intake
from rcbht_introspection.verify.model_file import load_usable_verifier
from rcbht_introspection.verify.stream import (
    NO_MODEL,
    VerifierOutput,
    VerifierStream,
    verifier_health,
)


class VerifierNode(ManagedNode):
    """Thin adapter: messages in -> VerifierStream -> Verdict messages and /task_health out."""

    def __init__(self) -> None:
        super().__init__("verifier_node", VerifierConfig)
        self.latency = LatencyWindow()
        self.watch = CounterWatch()

    def configure(self, cfg: VerifierConfig) -> None:
        self.cfg = cfg
        model, self.model_problem = load_usable_verifier(cfg.verifier_file, cfg.arms)
        self.model_sha256 = file_sha256(cfg.verifier_file)
        self.stream: VerifierStream | None = None
        if model is None:
            self.get_logger().error(
                f"no usable verifier, no verdicts, {cfg.health_topic} stays "
                f"{NO_MODEL!r}: {self.model_problem}"
            )
        else:
            self.stream = verifier_stream(model, cfg)
        self.subtask, self.published_health = "", ""
        self.qos = qos_profile(cfg.qos_depth, cfg.qos_reliability)
        self.verdict_pub = self.create_publisher(VerdictMsg, cfg.verdict_topic, self.qos)
        latched = qos_profile(1, cfg.qos_reliability)
        latched.durability = DurabilityPolicy.TRANSIENT_LOCAL
        self.health_pub = self.create_publisher(String, cfg.health_topic, latched)

    def activate(self) -> None:
        cfg = self.cfg
        if self.stream is not None:
            handlers = (self.sample, self.on_phase, self.on_tick)
            self.inputs = Intake(self, cfg, handlers, self.qos)
        self.create_subscription(BeliefMsg, cfg.belief_topic, self.on_belief, self.qos)
        if cfg.publish_rate_hz > 0:
            self.create_timer(1.0 / cfg.publish_rate_hz, self.publish_health)
        self.publish_health()
        self.get_logger().info(
            f"arms {list(cfg.arms)} from {list(cfg.wrench_topics)}, events on {cfg.phase_topic}, "
            f"verifier {cfg.verifier_file or '(none)'}, verdicts on {cfg.verdict_topic}, "
            f"health on {cfg.health_topic}"
        )

    def deactivate(self) -> None:
        if self.stream is not None:
            self.get_logger().info(self.stream.statistics())

    # --- input ---------------------------------------------------------------------------------
    def sample(self, arm: str, stamp: int, wrench: Sequence[float], source_ns: int | None) -> None:
        assert self.stream is not None  # subscribed only with a model
        t0 = time.perf_counter()
        out = self.stream.push(arm, stamp, wrench, source_ns)
        self.publish(out, t0)
        if out.rejected:
            self.get_logger().warning(
                f"dropped a wrench sample of arm {arm}: {out.rejected}",
                throttle_duration_sec=1.0,
            )

    def on_phase(self, name: str, source_ns: int | None) -> None:
        assert self.stream is not None
        out = self.stream.phase(name, source_ns)
        if out.unknown_phase is not None:
            self.get_logger().warning(f"ignored unknown /task_phase name {out.unknown_phase!r}")
        self.publish(out)

    def on_belief(self, msg: BeliefMsg) -> None:
        """The classifier's latest believed sub-task: the next verdicts' subtask field; a final
        verdict contradicting its commanded sub-task feeds the mismatch signal."""
        self.subtask = msg.subtask
        if self.stream is not None and msg.final:
            c = self.stream.belief(belief_from_msg(msg))
            if c is not None:
                self.get_logger().info(
                    f"sub-task {c.phase!r} from {c.start:.3f} s judged {c.subtask!r} "
                    f"(p {c.probability:.2f}): mismatch from stream time {c.time:.3f} s"
                )

    def on_tick(self, idle: bool) -> None:
        """Apply events that waited longer than the hold time for a later sample (no samples)."""
        if self.stream is not None and self.stream.segmenter.pending and idle:
            self.publish(self.stream.flush(time.time_ns()))

    # --- output --------------------------------------------------------------------------------
    def publish(self, out: VerifierOutput, t0: float | None = None) -> None:
        """The verdicts in tick order, then /task_health when it changed."""
        for sv in out.verdicts:
            self.verdict_pub.publish(verdict_msg(sv, self.subtask))
        if out.verdicts and t0 is not None:
            self.latency.add((time.perf_counter() - t0) * 1e3)
        if self.stream is not None and self.stream.health != self.published_health:
            self.publish_health()
        if alarm := out.alarm_line():
            self.get_logger().warning(alarm)

    def publish_health(self) -> None:
        """/task_health now (on change, and at publish_rate_hz)."""
        health = self.stream.health if self.stream is not None else NO_MODEL
        self.published_health = health
        self.health_pub.publish(String(data=health))

    def health(self, period_s: float) -> list[Health]:
        """Model, verdict latency of the period, rejected samples and events, current health."""
        matched = (
            self.verdict_pub.get_subscription_count(),
            self.inputs.publishers() if self.inputs else 0,
        )
        return verifier_health(
            self.stream,
            self.model_problem,
            (self.cfg.verifier_file, self.model_sha256),
            self.latency,
            self.watch,
            matched,
        )


def main(args: list[str] | None = None, stop: StopSignal | None = None) -> int:
    """Entry point (`ros2 run rcbht_introspection verifier_node`)."""
    return run(VerifierNode, "verifier_node", args, stop or StopSignal.install(until_up=True))


if __name__ == "__main__":
    sys.exit(main())

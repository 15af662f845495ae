"""classifier_node: RCBHT words -> the believed sub-task on /task_state and rcbht/belief.

Parameters: see config/classifier.yaml. Without a usable model (missing, unreadable, wrong
classes or taxonomy profile) it logs why once and publishes "unknown". /task_state is published
when the belief changes (once held `state_hold_s`) and at `publish_rate_hz`; each verdict on a
finished sub-task is a Belief with final=true.
"""

from __future__ import annotations

import sys
import time
from functools import partial

from rcbht_interfaces.msg import Belief as BeliefMsg
from rcbht_interfaces.msg import Phase as PhaseMsg
from rcbht_interfaces.msg import Words as WordsMsg
from std_msgs.msg import String

from rcbht_introspection.learn.models import load_subtask_model
from rcbht_introspection.live.belief import (
    UNKNOWN,
    Belief,
    BeliefTracker,
    StateFilter,
)
from rcbht_introspection.live.health import (
    CounterWatch,
    Health,
    LatencyWindow,
    classifier_health,
    file_sha256,
)
from rcbht_introspection.live.join import LatchedEvents
from rcbht_introspection.nodes.common import ManagedNode, phase_qos, qos_profile, run
from rcbht_introspection.nodes.conversions import belief_msg, to_ns, words_from_msg
from rcbht_introspection.nodes.draining import DrainedGroup, take
from rcbht_introspection.nodes.lifetime import StopSignal
from rcbht_introspection.nodes.params import ClassifierConfig, word_topics
from rcbht_introspection.taxonomy.words import LEVELS


class ClassifierNode(ManagedNode):
    """Thin adapter: Words / Phase messages -> BeliefTracker -> Belief and /task_state."""

    def __init__(self) -> None:
        super().__init__("classifier_node", ClassifierConfig)
        # predictions on one sample at a time: skip sklearn's per-call input validation
        sklearn_fast_predict()
        self.counts = {
            "words lost": 0,
            "sub-tasks judged unknown after a loss": 0,
            "latched events of earlier streams dropped": 0,
        }
        self.watch = CounterWatch()
        self.latency = LatencyWindow()

    def configure(self, cfg: ClassifierConfig) -> None:
        self.cfg = cfg
        model, self.model_problem = load_subtask_model(cfg.model_file, cfg.expected_profile)
        self.model_sha256 = file_sha256(cfg.model_file)
        if model is None:
            self.get_logger().error(
                f"no usable model, /task_state stays {UNKNOWN!r}: {self.model_problem}"
            )
        self.tracker = BeliefTracker(model, cfg.mode, cfg.window_s, end_phases=cfg.end_phases)
        self.stream: tuple[int, int] | None = None
        self.history: LatchedEvents[PhaseMsg] = LatchedEvents()
        self.state = StateFilter(cfg.state_hold_s)
        self.reported_error: str | None = None
        self.batches: dict[tuple[str, int], tuple[int, int]] = {}
        self.trigger_ns: int | None = None  # earliest sample behind the evidence not yet classified
        self.qos = qos_profile(cfg.qos_depth, cfg.qos_reliability)
        self.state_pub = self.create_publisher(String, cfg.state_topic, self.qos)
        self.belief_pub = self.create_publisher(BeliefMsg, cfg.belief_topic, self.qos)
        self.cpu_at_start = time.process_time()
        self.beliefs = 0

    def activate(self) -> None:
        cfg = self.cfg
        # events the latched rcbht/phase replays were published before this moment
        self.history.rejoin(time.time_ns())
        # the inputs are taken by drain() (draining.spin_draining), not by executor callbacks
        drained = DrainedGroup()
        self.word_subs = [
            (
                arm,
                self.create_subscription(
                    WordsMsg, topic, partial(self.ingest_words, arm), self.qos,
                    callback_group=drained,
                ),
            )
            for (arm, _), topic in word_topics(cfg.words_namespace, cfg.arms).items()
        ]  # fmt: skip
        self.phase_sub = self.create_subscription(
            PhaseMsg,
            cfg.phase_topic,
            self.ingest_phase,
            phase_qos(cfg.qos_reliability),
            callback_group=drained,
        )
        self.state_timer = (
            self.create_timer(1.0 / cfg.publish_rate_hz, self.publish_state)
            if cfg.publish_rate_hz > 0
            else None
        )
        self.publish_state()
        self.get_logger().info(
            f"mode {cfg.mode}, model {cfg.model_file or '(none)'}, classes {list(self.tracker.classes)}"
        )

    def deactivate(self) -> None:
        for _, sub in self.word_subs:
            self.destroy_subscription(sub)
        self.destroy_subscription(self.phase_sub)
        if self.state_timer is not None:
            self.destroy_timer(self.state_timer)
        self.word_subs = []
        self.get_logger().info(
            f"beliefs published {self.beliefs}, {self.counts}, "
            f"CPU {time.process_time() - self.cpu_at_start:.2f} s after configure"
        )

    def cleanup(self) -> None:
        self.destroy_publisher(self.state_pub)
        self.destroy_publisher(self.belief_pub)

    def health(self, period_s: float) -> list[Health]:
        """Model, belief-update latency of the period, words lost to a late join."""
        return [
            classifier_health(
                state=self.state_label,
                model_file=self.cfg.model_file,
                model_sha256=self.model_sha256,
                model_problem=self.model_problem,
                prediction_error=self.tracker.last_error,
                latency=self.latency,
                counts=self.counts,
                watch=self.watch,
            )
        ]

    def _enter(self, key: tuple[int, int]) -> None:
        """A live message of stream `key`: a new stream starts a new session (and its history)."""
        if key == self.stream:
            return
        if self.stream is not None and self.tracker.arms:
            # the previous stream ended without all its end markers: issue what it has
            for arm in tuple(self.tracker.arms):
                self.tracker.end_of_stream(arm)
            self.count_losses()
            for final in self.tracker.take_finals():
                self.publish_belief(final, 0)
        self.tracker.reset()
        self.state.new_stream()
        self.stream = key
        for event in self.history.stream_started(key):  # its events the latched topic replayed
            self._apply_phase(event)

    def ingest_words(self, arm: str, msg: WordsMsg) -> None:
        self._enter((to_ns(msg.time_origin), msg.stream_id))
        words, now = words_from_msg(msg)
        self.tracker.add_words(arm, words, now, LEVELS[msg.level], msg.seq_end)
        if msg.batch_size == 0:  # only the level's word numbering moved on: no new evidence
            return
        if msg.end_of_stream:
            self.tracker.end_of_stream(arm, LEVELS[msg.level])
        stamp = to_ns(msg.header.stamp)
        key = (arm, stamp)
        count, _ = self.batches.get(key, (0, msg.batch_size))
        self.batches[key] = (count + 1, msg.batch_size)
        self._trigger(stamp)

    def ingest_phase(self, msg: PhaseMsg, info: dict) -> None:
        key = (to_ns(msg.time_origin), msg.stream_id)
        published = info.get("source_timestamp")
        identity = (msg.name, msg.time)
        for event in self.history.event(key, msg, published, self.stream, identity):
            self._enter(key)
            self._apply_phase(event)
        self.counts["latched events of earlier streams dropped"] = self.history.stale

    def _apply_phase(self, msg: PhaseMsg) -> None:
        if not self.tracker.phase(msg.name, msg.time):
            self.get_logger().warning(f"ignored unknown sub-task event {msg.name!r}")
            return
        self._trigger(to_ns(msg.header.stamp))

    def _trigger(self, stamp: int) -> None:
        self.trigger_ns = stamp if self.trigger_ns is None else min(self.trigger_ns, stamp)

    def drain(self) -> None:
        """Take every message already delivered, then classify once (not once per message).

        A belief is computed once all level messages of the newest sample's batch are in; its
        trigger is the earliest sample behind the new evidence (the conservative latency).
        The burst is handled in publication order (DDS source timestamps of one publisher).
        """
        taken: list[tuple[int, str | None, tuple]] = []
        for _ in range(10000):
            before = len(taken)
            for arm, sub in self.word_subs:
                if (got := take(sub)) is not None:
                    taken.append((got[1].get("source_timestamp", 0), arm, got))
            if (got := take(self.phase_sub)) is not None:
                taken.append((got[1].get("source_timestamp", 0), None, got))
            if len(taken) == before:
                break
        # each topic delivers in order, but not the topics among themselves: handle the burst
        # in publication order (a stream's last words before the next stream's first event)
        taken.sort(key=lambda t: t[0])
        for _, arm, (msg, info) in taken:
            if arm is None:
                self.ingest_phase(msg, info)
            else:
                self.ingest_words(arm, msg)
        newest = max((k[1] for k in self.batches), default=None)
        if any(n < size for (_, stamp), (n, size) in self.batches.items() if stamp == newest):
            return  # the other level messages of this sample are on their way
        self.batches = {}
        if self.trigger_ns is not None:
            trigger, self.trigger_ns = self.trigger_ns, None
            self.update(trigger)

    def update(self, trigger_ns: int) -> None:
        """Publish finished sub-task verdicts, then the current belief and a changed state."""
        t0 = time.perf_counter()
        self.count_losses()
        for final in self.tracker.take_finals():
            self.publish_belief(final, trigger_ns)
        belief = self.tracker.current()
        self.publish_belief(belief, trigger_ns)
        if self.state.update(self.tracker.now, belief.subtask):
            self.publish_state()
        self.latency.add((time.perf_counter() - t0) * 1e3)
        error = self.tracker.last_error
        if error and error != self.reported_error:
            self.reported_error = error
            self.get_logger().error(f"model prediction failed, publishing {UNKNOWN!r}: {error}")

    def count_losses(self) -> None:
        """Words proven lost since the last call: counted, and said once per loss."""
        lost = self.tracker.account_losses()
        if lost:
            self.counts["words lost"] += lost
            self.get_logger().warning(
                f"{lost} words of this stream never arrived (joined late or lost): the sub-task "
                f"under way is judged {UNKNOWN!r} until the next boundary"
            )

    def publish_belief(self, belief: Belief, trigger_ns: int) -> None:
        if belief.final and belief.blind:
            self.counts["sub-tasks judged unknown after a loss"] += 1
        self.beliefs += 1
        self.belief_pub.publish(belief_msg(belief, time.time_ns(), trigger_ns))

    def publish_state(self) -> None:
        self.state_pub.publish(String(data=self.state.state))


def sklearn_fast_predict() -> None:
    """Per-sample predictions: skip scikit-learn's input validation (features are finite)."""
    try:
        import sklearn

        sklearn.set_config(assume_finite=True, skip_parameter_validation=True)
    except ImportError:  # no model can load without it anyway
        pass


def main(args: list[str] | None = None, stop: StopSignal | None = None) -> int:
    """Entry point (`ros2 run rcbht_introspection classifier_node`)."""
    return run(ClassifierNode, "classifier_node", args, stop or StopSignal.install())


if __name__ == "__main__":
    sys.exit(main())

"""classifier_node: RCBHT words -> the believed sub-task on /task_state and rcbht/belief.

Parameters: see config/classifier.yaml. Without a usable model (missing, unreadable, wrong
classes or taxonomy profile) it logs why once and publishes "unknown". /task_state is published
when it changes (a new sub-task once confident, parameters `state.*`) and at
`publish_rate_hz`; each verdict on a finished sub-task is a Belief with final=true. With
`teach_enabled`, labels for windows (service ~/teach, topic `teach_topic`) are learned beside
the live path (learn/teaching.py); a missing model_file is then a cold start.
"""

from __future__ import annotations

import sys
import time
from functools import partial

from rcbht_interfaces.msg import Belief as BeliefMsg
from rcbht_interfaces.msg import Phase as PhaseMsg
from rcbht_interfaces.msg import TeachRequest as TeachRequestMsg
from rcbht_interfaces.msg import Words as WordsMsg
from rcbht_interfaces.srv import Teach
from rclpy.subscription import Subscription
from std_msgs.msg import String

from rcbht_introspection import messages
from rcbht_introspection.configure.model_source import classifier_model, teaching_values
from rcbht_introspection.configure.params import ClassifierConfig, word_topics
from rcbht_introspection.configure.sessions import classifier_session
from rcbht_introspection.learn.teaching import Teaching
from rcbht_introspection.lifetime import StopSignal
from rcbht_introspection.live.classifier import PhaseInput, WordsInput
from rcbht_introspection.live.health import CounterWatch, Health, LatencyWindow, classifier_health
from rcbht_introspection.live.order import Arrivals
from rcbht_introspection.nodes.common import ManagedNode, phase_qos, qos_profile, run
from rcbht_introspection.nodes.intake import fewest_publishers


class ClassifierNode(ManagedNode):
    """Thin adapter: Words / Phase messages -> ClassifierSession -> Belief and /task_state."""

    def __init__(self) -> None:
        super().__init__("classifier_node", ClassifierConfig)
        self.counts: dict[str, int] = {}  # kept across reconfigures (live/classifier.COUNTS)
        self.watch, self.latency = CounterWatch(), LatencyWindow()
        self.teaching: Teaching | None = None
        self.arrivals: Arrivals[WordsInput | PhaseInput] = Arrivals()
        self.input_subs: list[Subscription] = []  # words, then events: while active

    def configure(self, cfg: ClassifierConfig) -> None:
        self.cfg = cfg
        self.source, self.teaching, notes = classifier_model(cfg, self.counts)
        self.log_notes(notes)
        model = self.source.model
        self.session = classifier_session(cfg, model, self.counts, self.teaching)
        self.qos = qos_profile(cfg.qos_depth, cfg.qos_reliability)
        self.state_pub = self.create_publisher(String, cfg.state_topic, self.qos)
        self.belief_pub = self.create_publisher(BeliefMsg, cfg.belief_topic, self.qos)
        self.cpu_at_start, self.beliefs = time.process_time(), 0

    def activate(self) -> None:
        cfg = self.cfg
        self.session.rejoin(time.time_ns())  # latched events before now are history
        self.input_subs = [
            self.subscribe(WordsMsg, topic, partial(self.on_words, arm), self.qos)
            for (arm, _), topic in word_topics(cfg.words_namespace, cfg.arms).items()
        ]
        phases = self.subscribe(
            PhaseMsg, cfg.phase_topic, self.on_phase, phase_qos(cfg.qos_reliability)
        )
        self.input_subs.append(phases)
        self.create_service(Teach, "~/teach", self.on_teach)
        self.create_subscription(
            TeachRequestMsg, cfg.teach_topic, self.on_teach_topic, qos_profile(100, "reliable")
        )
        rate = cfg.publish_rate_hz
        if rate > 0:
            self.create_timer(1.0 / rate, self.publish_state)
        self.publish_state()
        self.get_logger().info(
            f"mode {cfg.mode}, model {cfg.model_file or '(none)'}, classes "
            f"{list(self.session.tracker.classes)}{self.source.about()}"
        )

    def deactivate(self) -> None:
        self.input_subs = []
        cpu = time.process_time() - self.cpu_at_start
        self.get_logger().info(
            f"beliefs published {self.beliefs}, {self.counts}, CPU {cpu:.2f} s after configure"
        )

    def cleanup(self) -> None:
        if self.teaching is not None:
            self.teaching.close()
        self.log_teaching()

    def health(self, period_s: float) -> list[Health]:
        """Model, belief-update latency, words lost to a late join, the fewest publishers its
        readers matched on any input (a harness waits for >= 1), teaching."""
        extra = [("input publishers matched", str(fewest_publishers(self.input_subs)))]
        self.log_teaching()
        extra += teaching_values(self.teaching) if self.teaching is not None else []
        model = self.source.status(self.session.tracker.last_error)
        return [
            classifier_health(self.state_label, model, self.latency, self.counts, self.watch, extra)
        ]

    def log_teaching(self) -> None:
        """Log what teaching did since the last call (each a line)."""
        self.log_notes(self.teaching.notes() if self.teaching is not None else [])

    def on_teach(self, request: Teach.Request, response: Teach.Response) -> Teach.Response:
        """The ~/teach service: take the window's words now, learn them in the worker."""
        status = self.session.teach(messages.teach_request(request))
        self.log_teaching()
        return messages.teach_response(response, status)

    def on_teach_topic(self, msg: TeachRequestMsg) -> None:
        """A fire-and-forget label: as the service, an empty label is refused (and counted)."""
        if refused := self.session.teach_topic(messages.teach_request(msg), self.cfg.teach_topic):
            self.get_logger().warning(refused)
        self.log_teaching()

    def on_words(self, arm: str, msg: WordsMsg, published: int | None) -> None:
        self.arrivals.add(published, messages.words_input(arm, msg))

    def on_phase(self, msg: PhaseMsg, published: int | None) -> None:
        self.arrivals.add(published, messages.phase_input(msg, published))

    def settled(self) -> None:
        """The inputs go to the session in publication order (live/order.py), which classifies
        where they say, so /task_state does not depend on how they were grouped in delivery."""
        items = self.arrivals.release()
        if not items:
            return
        step = self.session.receive(item for _, item in items)
        self.log_notes(step.notes())
        for belief, trigger_ns in step.beliefs:
            self.beliefs += 1
            self.belief_pub.publish(messages.belief_msg(belief, time.time_ns(), trigger_ns))
        for _, state in step.states:
            self.state_pub.publish(String(data=state))
        for ms in step.update_ms:
            self.latency.add(ms)
        if step.model_swapped and self.teaching is not None:
            self.source.taught(self.cfg, self.teaching)  # /diagnostics names the file in use

    def publish_state(self) -> None:
        self.state_pub.publish(String(data=self.session.state.state))


def main(args: list[str] | None = None, stop: StopSignal | None = None) -> int:
    """Entry point (`ros2 run rcbht_introspection classifier_node`)."""
    return run(ClassifierNode, "classifier_node", args, stop or StopSignal.install(until_up=True))


if __name__ == "__main__":
    sys.exit(main())

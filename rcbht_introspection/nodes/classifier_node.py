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
from pathlib import Path

from rcbht_interfaces.msg import Belief as BeliefMsg
from rcbht_interfaces.msg import Phase as PhaseMsg
from rcbht_interfaces.msg import TeachRequest as TeachRequestMsg
from rcbht_interfaces.msg import Words as WordsMsg
from rcbht_interfaces.srv import Teach
from rclpy.subscription import Subscription
from std_msgs.msg import String

from rcbht_introspection.learn.live import load_live_config
from rcbht_introspection.learn.model_file import load_subtask_model
from rcbht_introspection.learn.models import SubtaskModel
from rcbht_introspection.learn.online import load_teach_config
from rcbht_introspection.learn.teaching import Teaching
from rcbht_introspection.live.belief import UNKNOWN, Belief, BeliefTracker
from rcbht_introspection.live.classifier import ClassifierSession, PhaseInput, Step, WordsInput
from rcbht_introspection.live.health import (
    CounterWatch,
    Health,
    LatencyWindow,
    classifier_health,
    file_sha256,
)
from rcbht_introspection.live.order import Arrivals
from rcbht_introspection.live.state import StateFilter
from rcbht_introspection.live.teach import TeachRequest, TeachStatus
from rcbht_introspection.nodes.common import ManagedNode, phase_qos, qos_profile, run
from rcbht_introspection.nodes.conversions import belief_msg, phase_input, words_input
from rcbht_introspection.nodes.intake import fewest_publishers
from rcbht_introspection.nodes.lifetime import StopSignal
from rcbht_introspection.nodes.params import ClassifierConfig, word_topics


class ClassifierNode(ManagedNode):
    """Thin adapter: Words / Phase messages -> BeliefTracker -> Belief and /task_state."""

    def __init__(self) -> None:
        super().__init__("classifier_node", ClassifierConfig)
        self.counts: dict[str, int] = {}  # kept across reconfigures (live/classifier.COUNTS)
        self.watch = CounterWatch()
        self.latency = LatencyWindow()
        self.teaching: Teaching | None = None
        self.arrivals: Arrivals[WordsInput | PhaseInput] = Arrivals()
        """Inputs the executor delivered since the last settled()."""
        self.input_subs: list[Subscription] = []
        """The words subscriptions, then the events subscription, while active."""

    def spin_kind(self) -> str:
        """The `spin` parameter, except with teaching on: then rclpy's SingleThreadedExecutor.
        Under the EventsExecutor the ~/teach service went unanswered for 20 s beside a busy
        machine (test_ros_teach's cold start, once in three CI runs)."""
        spin = super().spin_kind()
        if spin == "events" and self.get_parameter("teach_enabled").value:
            return "executor"
        return spin

    def configure(self, cfg: ClassifierConfig) -> None:
        self.cfg = cfg
        # a teaching node continues from the model it saved (teach_file), else model_file
        taught = cfg.teach_enabled and cfg.teach_file and Path(cfg.teach_file).is_file()
        self.model_source = cfg.teach_file if taught else cfg.model_file
        model, self.model_problem = load_subtask_model(self.model_source, cfg.expected_profile)
        self.model_taxonomy = (
            f", taxonomy profile {model.taxonomy_profile} "
            f"(sha256 {model.taxonomy_sha256[:12] or 'not recorded'})"
            if model is not None
            else ""
        )
        self.model_sha256 = file_sha256(self.model_source)
        cold = cfg.teach_enabled and model is None and not Path(self.model_source).is_file()
        if cold:
            self.model_problem = ""
            self.get_logger().info(
                f"cold start: no model yet ({self.model_source or 'model_file not set'}), "
                f"/task_state stays {UNKNOWN!r} until the first taught window"
            )
        elif model is None:
            self.get_logger().error(
                f"no usable model, /task_state stays {UNKNOWN!r}: {self.model_problem}"
            )
        self.teaching = self.make_teaching(cfg, model, cold) if cfg.teach_enabled else None
        self.tracker = BeliefTracker(
            model,
            cfg.mode,
            cfg.window_s,
            end_phases=cfg.end_phases,
            history_s=cfg.teach_history_s if cfg.teach_enabled else 0.0,
        )
        self.session = ClassifierSession(
            self.tracker, StateFilter(cfg.state), self.counts, self.teaching
        )
        self.reported_error: str | None = None
        self.qos = qos_profile(cfg.qos_depth, cfg.qos_reliability)
        self.state_pub = self.create_publisher(String, cfg.state_topic, self.qos)
        self.belief_pub = self.create_publisher(BeliefMsg, cfg.belief_topic, self.qos)
        self.cpu_at_start = time.process_time()
        self.beliefs = 0

    def make_teaching(
        self, cfg: ClassifierConfig, model: SubtaskModel | None, cold: bool
    ) -> Teaching:
        """The teach queue and worker; a model file that exists but is unusable is not
        overwritten (teaching refuses, saying why)."""
        config = load_teach_config(cfg.teach_config_file or None)
        save = self.teaching_file()
        profile = cfg.expected_profile or "reference"  # what a cold-started model records
        unusable = (
            f"model file {self.model_source} exists but is not usable ({self.model_problem}); "
            "teaching would overwrite it"
            if model is None and not cold
            else ""
        )
        teaching = Teaching(
            config,
            model,
            save,
            self.counts,
            taxonomy_profile=profile,
            live_windows=load_live_config(),  # running windows are taught too (config/live.yaml)
            unavailable=unusable,  # then no learner process is started
        )
        if teaching.unavailable:
            self.get_logger().error(f"teaching is unavailable: {teaching.unavailable}")
        elif not save:
            self.get_logger().warning("teaching: taught models are not saved (no teach_file)")
        return teaching

    def teaching_file(self) -> str:
        """Where taught models are saved ('' when they are not)."""
        return self.cfg.teach_file or self.cfg.model_file

    def activate(self) -> None:
        cfg = self.cfg
        # events the latched rcbht/phase replays were published before this moment
        self.session.rejoin(time.time_ns())
        self.input_subs = [
            self.subscribe(WordsMsg, topic, partial(self.on_words, arm), self.qos)
            for (arm, _), topic in word_topics(cfg.words_namespace, cfg.arms).items()
        ]
        self.input_subs.append(
            self.subscribe(PhaseMsg, cfg.phase_topic, self.on_phase, phase_qos(cfg.qos_reliability))
        )
        self.teach_srv = self.create_service(Teach, "~/teach", self.on_teach)
        self.teach_sub = self.create_subscription(
            TeachRequestMsg, cfg.teach_topic, self.on_teach_topic, qos_profile(100, "reliable")
        )
        self.state_timer = (
            self.create_timer(1.0 / cfg.publish_rate_hz, self.publish_state)
            if cfg.publish_rate_hz > 0
            else None
        )
        self.publish_state()
        self.get_logger().info(
            f"mode {cfg.mode}, model {cfg.model_file or '(none)'}, classes "
            f"{list(self.tracker.classes)}{self.model_taxonomy}"
        )

    def deactivate(self) -> None:
        for sub in self.input_subs:
            self.destroy_subscription(sub)
        self.destroy_subscription(self.teach_sub)
        self.destroy_service(self.teach_srv)
        if self.state_timer is not None:
            self.destroy_timer(self.state_timer)
        self.input_subs = []
        self.get_logger().info(
            f"beliefs published {self.beliefs}, {self.counts}, "
            f"CPU {time.process_time() - self.cpu_at_start:.2f} s after configure"
        )

    def cleanup(self) -> None:
        self.destroy_publisher(self.state_pub)
        self.destroy_publisher(self.belief_pub)
        if self.teaching is not None:
            self.teaching.close()
            self.log_teach_notes()

    def health(self, period_s: float) -> list[Health]:
        """Model, belief-update latency of the period, words lost to a late join, the fewest
        publishers its readers matched on any input (a harness waits for >= 1), teaching."""
        matched = fewest_publishers(self.input_subs)
        extra: list[tuple[str, str]] = [("input publishers matched", str(matched))]
        if self.teaching is not None:
            self.log_teach_notes()
            status = self.teaching.status()
            extra += [
                ("taught windows", str(status.taught_windows)),
                ("teach requests pending", str(status.pending)),
                ("taught model version", str(status.model_version)),
                ("teach learner", self.teaching.where_learned()),
            ]
        return [
            classifier_health(
                state=self.state_label,
                model_file=self.model_source,
                model_sha256=self.model_sha256,
                model_problem=self.model_problem,
                prediction_error=self.tracker.last_error,
                latency=self.latency,
                counts=self.counts,
                watch=self.watch,
                extra=extra,
            )
        ]

    def on_teach(self, request: Teach.Request, response: Teach.Response) -> Teach.Response:
        """The ~/teach service: take the window's words now, learn them in the worker."""
        status = self.session.teach(
            TeachRequest(
                request.label, request.last, request.start, request.end, request.request_id
            )
        )
        self.log_teach_notes()
        response.accepted = status.accepted
        response.message = status.message
        response.pending = status.pending
        response.taught_windows = status.taught_windows
        response.model_version = status.model_version
        response.errors = status.errors
        return response

    def on_teach_topic(self, msg: TeachRequestMsg) -> None:
        """A fire-and-forget label: as the service, an empty label is refused (and counted)."""
        if not msg.label:
            self.counts.setdefault("teach requests refused", 0)
            self.counts["teach requests refused"] += 1
            self.get_logger().warning(
                f"teach request refused: empty label on {self.cfg.teach_topic}"
            )
            return
        status: TeachStatus = self.session.teach(
            TeachRequest(msg.label, msg.last, msg.start, msg.end, msg.request_id)
        )
        self.log_teach_notes()
        if not status.accepted and self.teaching is None:
            self.get_logger().warning(f"teach request refused: {status.message}")

    def log_teach_notes(self) -> None:
        """Log what teaching did since the last call (each a line)."""
        if self.teaching is None:
            return
        log = self.get_logger()
        for level, line in self.teaching.notes():
            {"info": log.info, "warning": log.warning}.get(level, log.error)(line)

    def on_words(self, arm: str, msg: WordsMsg, published: int | None) -> None:
        """One Words message: handed over with what else arrived, at settled()."""
        self.arrivals.add(published, words_input(arm, msg))

    def on_phase(self, msg: PhaseMsg, published: int | None) -> None:
        """One Phase message: handed over with what else arrived, at settled()."""
        self.arrivals.add(published, phase_input(msg, published))

    def settled(self) -> None:
        """The executor ran what was delivered: the inputs go to the session in publication
        order (live/order.py), which classifies where they say, not once per burst, so
        /task_state does not depend on how DDS or the executor grouped them."""
        items = self.arrivals.release()
        if items:
            self.publish_step(self.session.receive(item for _, item in items))

    def publish_step(self, step: Step) -> None:
        """Publish what the session produced (verdicts and beliefs, then each /task_state
        change), and say what it noticed."""
        for name in step.ignored_events:
            self.get_logger().warning(f"ignored unknown sub-task event {name!r}")
        if step.lost:
            self.get_logger().warning(
                f"{step.lost} words of this stream never arrived (joined late or lost): the "
                f"sub-task under way is judged {UNKNOWN!r} until the next boundary"
            )
        for belief, trigger_ns in step.beliefs:
            self.publish_belief(belief, trigger_ns)
        for _, state in step.states:
            self.state_pub.publish(String(data=state))
        for ms in step.update_ms:
            self.latency.add(ms)
        if step.model_swapped and self.teaching is not None and self.teaching.saved_sha256:
            # /diagnostics names the file of the model in use (hashed by the teach worker)
            self.model_source = self.teaching_file()
            self.model_sha256 = self.teaching.saved_sha256
        error = self.tracker.last_error
        if error and error != self.reported_error:
            self.reported_error = error
            self.get_logger().error(f"model prediction failed, publishing {UNKNOWN!r}: {error}")

    def publish_belief(self, belief: Belief, trigger_ns: int) -> None:
        self.beliefs += 1
        self.belief_pub.publish(belief_msg(belief, time.time_ns(), trigger_ns))

    def publish_state(self) -> None:
        self.state_pub.publish(String(data=self.session.state.state))


def main(args: list[str] | None = None, stop: StopSignal | None = None) -> int:
    """Entry point (`ros2 run rcbht_introspection classifier_node`)."""
    return run(ClassifierNode, "classifier_node", args, stop or StopSignal.install(until_up=True))


if __name__ == "__main__":
    sys.exit(main())

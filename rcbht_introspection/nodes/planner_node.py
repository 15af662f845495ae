"""planner_node: the reference planner. ~/run_trial starts a trial; each attempt is a goal of
the robot's Attempt action; verdicts on rcbht/verdict may cancel it (abort) and the results
choose the next correction, all decided by plan/planner.py. Every decision goes out on
rcbht/decision. Without a verifier file, introspect says so once and runs retry.
Parameters: config/planner.yaml.
"""

from __future__ import annotations

import sys

from rcbht_interfaces.action import Attempt as AttemptAction
from rcbht_interfaces.msg import PlanDecision
from rcbht_interfaces.msg import Verdict as VerdictMsg
from rcbht_interfaces.srv import RunTrial
from rclpy.action.client import ActionClient, ClientGoalHandle
from rclpy.task import Future

from rcbht_introspection.configure.params import PlannerConfig
from rcbht_introspection.lifetime import StopSignal
from rcbht_introspection.nodes.common import ManagedNode, qos_profile, run
from rcbht_introspection.plan.planner import Decision, Planner, Report, make_planner
from rcbht_introspection.plan.recovery import Correction, load_recovery_config
from rcbht_introspection.verify.model_file import load_verifier


class PlannerNode(ManagedNode):
    """Thin adapter: trials, verdicts and attempt results in -> Planner -> goals and decisions."""

    def __init__(self) -> None:
        super().__init__("planner_node", PlannerConfig)

    def configure(self, cfg: PlannerConfig) -> None:
        self.cfg = cfg
        self.table = load_recovery_config("snap", cfg.recovery_file or None)
        self.trained_on = load_verifier(cfg.verifier_file).trained_on if cfg.verifier_file else None
        if self.trained_on is None and cfg.policy == "introspect":
            self.get_logger().warning("no verifier file: policy introspect runs as retry")
        self.planner: Planner | None = None
        self.goal: ClientGoalHandle | None = None
        self.trial, self.last_stream, self.stream_floor = 0, -1, 0
        self.qos = qos_profile(cfg.qos_depth, cfg.qos_reliability)
        self.decision_pub = self.create_publisher(PlanDecision, cfg.decision_topic, self.qos)

    def activate(self) -> None:
        self.client = ActionClient(self, AttemptAction, self.cfg.attempt_action)
        self.create_subscription(VerdictMsg, self.cfg.verdict_topic, self.on_verdict, self.qos)
        self.create_service(RunTrial, "~/run_trial", self.on_run_trial)

    def deactivate(self) -> None:
        self.client.destroy()
        self.get_logger().info(f"trials run: {self.trial}")

    def on_run_trial(self, req: RunTrial.Request, res: RunTrial.Response) -> RunTrial.Response:
        if self.planner is not None:
            res.message = f"trial {self.trial} is running"
            return res
        if not self.client.server_is_ready():
            res.message = f"no Attempt action server at {self.cfg.attempt_action}"
            return res
        truth = Correction(*req.truth) if len(req.truth) == 4 else None
        if self.cfg.policy == "oracle" and truth is None:
            res.message = "the oracle policy needs the trial's truth (4 values)"
            return res
        self.trial = int(req.trial)
        self.planner = make_planner(self.cfg.policy, self.table, self.trained_on, truth)
        self.send(self.planner.first())
        res.accepted, res.message = True, f"trial {self.trial}: {self.planner.policy}"
        return res

    def send(self, decision: Decision) -> None:
        """Publish the decision; start the attempt it names, or end the trial."""
        self.publish(decision)
        if decision.kind == "stop":
            self.planner, self.goal = None, None
            return
        c = decision.correction
        goal = AttemptAction.Goal(dx=c.x, dy=c.y, dz=c.z, dyaw=c.yaw, attempt=decision.attempt)
        self.stream_floor = self.last_stream + 1  # verdicts of this attempt's stream on
        self.client.send_goal_async(goal).add_done_callback(self.on_goal)

    def on_goal(self, future: Future) -> None:
        handle = future.result()
        if self.planner is None or handle is None:
            return
        if not handle.accepted:
            self.send(self.planner.ended(Report(False, "rejected"), 0.0))
            return
        self.goal = handle
        handle.get_result_async().add_done_callback(self.on_result)

    def on_result(self, future: Future) -> None:
        if self.planner is None:
            return
        r = future.result().result
        self.goal = None
        self.send(self.planner.ended(Report(r.seated, r.reason), r.duration))

    def on_verdict(self, msg: VerdictMsg) -> None:
        self.last_stream = max(self.last_stream, int(msg.stream_id))
        if self.planner is None or self.goal is None or msg.stream_id < self.stream_floor:
            return
        directions = dict(zip(msg.direction_axes, msg.directions, strict=False))
        ranked = dict(zip(msg.classes, msg.probabilities, strict=False))
        abort = self.planner.verdict(msg.time, msg.alarm, msg.failure_class, directions, ranked)
        if abort is not None:
            self.publish(abort)
            self.goal.cancel_goal_async()

    def publish(self, d: Decision) -> None:
        c = d.correction
        self.decision_pub.publish(
            PlanDecision(
                trial=self.trial, policy=self.cfg.policy, kind=d.kind, attempt=d.attempt,
                time=d.time, dx=c.x, dy=c.y, dz=c.z, dyaw=c.yaw,
                failure_class=d.failure_class, reason=d.reason,
            )
        )  # fmt: skip


def main(args: list[str] | None = None, stop: StopSignal | None = None) -> int:
    """Entry point (`ros2 run rcbht_introspection planner_node`)."""
    return run(PlannerNode, "planner_node", args, stop or StopSignal.install(until_up=True))


if __name__ == "__main__":
    sys.exit(main())

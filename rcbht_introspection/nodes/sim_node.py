"""sim_node: the simulated snap cell as a robot. ~/start_trial draws a trial's world; each goal
of the ~/attempt action runs one attempt in (rate_factor x) real time, publishing the arm's
wrench and the controller's sub-task events; cancel is abort (the arm backs off). The stepping
is sim/episode.py's; a goal whose correction is not finite or beyond the recovery table's
bounds ends at once as `rejected`, with no motion. Parameters: config/sim_node.yaml.
"""

from __future__ import annotations

import sys
import time
from typing import TYPE_CHECKING

from geometry_msgs.msg import WrenchStamped
from rcbht_interfaces.action import Attempt as AttemptAction
from rcbht_interfaces.srv import StartTrial
from rclpy.action.server import ActionServer, CancelResponse, ServerGoalHandle
from rclpy.task import Future
from std_msgs.msg import String

from rcbht_introspection.config_files import config_path
from rcbht_introspection.configure.params import SimNodeConfig
from rcbht_introspection.errors import InputError
from rcbht_introspection.io.bags import END_PHASE
from rcbht_introspection.lifetime import StopSignal
from rcbht_introspection.messages import to_time
from rcbht_introspection.nodes.common import ManagedNode, qos_profile, run
from rcbht_introspection.plan.recovery import Correction, load_recovery_config

if TYPE_CHECKING:  # the simulator (MuJoCo, the sim extra) is imported when the node configures
    from rcbht_introspection.sim.episode import Attempt, World

RATE_HZ = 200.0
STEP_S = 0.005
"""Wall seconds between two steps of the running attempt (each publishes the samples due)."""


class SimNode(ManagedNode):
    """Thin adapter: ~/start_trial and ~/attempt in -> episode -> wrench and events out."""

    def __init__(self) -> None:
        super().__init__("sim_node", SimNodeConfig)

    def configure(self, cfg: SimNodeConfig) -> None:
        try:
            from rcbht_introspection.sim import load_sim_config
        except ImportError as exc:
            raise InputError(
                f"sim_node needs the simulator's MuJoCo (the sim extra): {exc}"
            ) from None
        self.cfg = cfg
        self.sim = load_sim_config(cfg.sim_config or config_path("sim/cell.yaml"))
        self.bounds = load_recovery_config("snap", cfg.recovery_file or None).bounds
        self.world: World | None = None
        self.attempt: Attempt | None = None
        self.published = 0
        self.qos = qos_profile(cfg.qos_depth, cfg.qos_reliability)
        self.wrench_pub = self.create_publisher(WrenchStamped, cfg.wrench_topic, self.qos)
        self.phase_pub = self.create_publisher(String, cfg.phase_topic, self.qos)

    def activate(self) -> None:
        self.create_service(StartTrial, "~/start_trial", self.on_start_trial)
        self.server = ActionServer(
            self,
            AttemptAction,
            "~/attempt",
            execute_callback=self.execute,
            cancel_callback=lambda handle: CancelResponse.ACCEPT,
        )
        self.create_timer(STEP_S, self.on_step)

    def deactivate(self) -> None:
        self.server.destroy()
        seed = self.world.seed if self.world else "none"
        self.get_logger().info(f"samples published {self.published}, last trial {seed}")

    def on_start_trial(
        self, req: StartTrial.Request, res: StartTrial.Response
    ) -> StartTrial.Response:
        if self.attempt is not None:
            res.message = "an attempt is running"
            return res
        from rcbht_introspection.sim.episode import draw_world

        try:
            self.world = draw_world(self.sim, int(req.seed), req.failure or None)
        except InputError as exc:
            res.message = str(exc)
            return res
        res.accepted, res.as_requested = True, self.world.as_requested
        res.truth = list(self.world.truth)
        res.message = f"trial {req.seed}: {req.failure or 'nominal'}"
        return res

    async def execute(self, handle: ServerGoalHandle) -> AttemptAction.Result:
        goal = handle.request
        correction = Correction(goal.dx, goal.dy, goal.dz, goal.dyaw)
        problem = correction.problem(self.bounds)
        problem = problem or ("" if self.world else "no trial started (~/start_trial)")
        problem = problem or ("an attempt is running" if self.attempt else "")
        if problem or self.world is None:
            handle.abort()
            return AttemptAction.Result(reason="rejected", message=problem)
        from rcbht_introspection.sim.episode import Attempt

        index = int(goal.attempt) - 1
        self.attempt = Attempt(self.sim, self.world, correction.values(), index, RATE_HZ)
        self.goal, self.ended, self.started = handle, Future(), time.monotonic()
        self.origin_ns = self.get_clock().now().nanoseconds
        await self.ended
        end, self.attempt = self.attempt.end, None
        assert end is not None
        handle.canceled() if handle.is_cancel_requested else handle.succeed()
        return AttemptAction.Result(
            seated=end.seated, reason=end.reason, part_seated=end.latched,
            duration=end.duration, return_s=float(end.return_s), message="",
        )  # fmt: skip

    def on_step(self) -> None:
        """Publish the samples due by now (rate_factor x the wall time since the start)."""
        attempt = self.attempt
        if attempt is None or self.ended.done():
            return
        if self.goal.is_cancel_requested:
            attempt.abort()
        due = (time.monotonic() - self.started) * self.cfg.rate_factor * RATE_HZ
        while attempt.samples <= due:
            sample = attempt.step()
            if sample is None:
                self._event(END_PHASE)
                self.ended.set_result(True)
                return
            for _, name in sample.events:
                self._event(name)
                self.goal.publish_feedback(AttemptAction.Feedback(subtask=name, time=sample.time))
            self._publish(sample.time, sample.wrench)

    def _publish(self, t: float, w: object) -> None:
        msg = WrenchStamped()
        msg.header.stamp = to_time(self.origin_ns + round(t * 1e9))
        msg.header.frame_id = self.cfg.frame_id
        f, m = msg.wrench.force, msg.wrench.torque
        f.x, f.y, f.z, m.x, m.y, m.z = (float(v) for v in w)  # type: ignore[attr-defined]
        self.wrench_pub.publish(msg)
        self.published += 1

    def _event(self, name: str) -> None:
        self.phase_pub.publish(String(data=name))


def main(args: list[str] | None = None, stop: StopSignal | None = None) -> int:
    """Entry point (`ros2 run rcbht_introspection sim_node`)."""
    return run(SimNode, "sim_node", args, stop or StopSignal.install(until_up=True))


if __name__ == "__main__":
    sys.exit(main())

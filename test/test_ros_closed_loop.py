"""The closed loop over real DDS: sim_node, segmenter_node, verifier_node and planner_node as
processes of their own decide as the in-process loop does on the same worlds; sim_node rejects
a bad goal without moving; each of the five nodes exits 0 on SIGINT in the middle of an
attempt."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest
from ros_support import require_ros

from rcbht_introspection.cli import main
from rcbht_introspection.configure.params import (
    ClassifierConfig,
    PlannerConfig,
    SegmenterConfig,
    SimNodeConfig,
    VerifierConfig,
)
from rcbht_introspection.replay.supervision import (
    NodeProcess,
    lease_domain,
    release_domain,
    ros_env,
    wait_for_nodes,
    write_params,
)

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def _small_verifier(path: Path) -> Path:
    """A verifier of the cell trained on a few trials of other seeds (as the default, smaller)."""
    from rcbht_introspection.closed_loop.experiment import train_default_verifier
    from rcbht_introspection.config_files import config_path
    from rcbht_introspection.sim import load_sim_config
    from rcbht_introspection.verify.config import load_verify_config
    from rcbht_introspection.verify.model_file import save_verifier

    cell = load_sim_config(config_path("sim/cell.yaml"))
    classes = ("deviation_x+", "jamming")
    model = train_default_verifier(cell, classes, load_verify_config(), 0, 2, 12)
    return save_verifier(model, path)


def test_the_nodes_decide_as_the_in_process_loop_on_the_same_worlds(tmp_path: Path) -> None:
    require_ros()
    out = tmp_path / "loop.json"
    verifier = _small_verifier(tmp_path / "verifier.npz")
    args = ["closed-loop", "--trials", "2", "--nominal", "1", "--classes", "deviation_x+,jamming",
            "--policy", "introspect", "--verifier", str(verifier), "--ros", str(tmp_path / "ros"),
            "--rate-factor", "8"]  # fmt: skip
    assert main([*args, "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    ros = result["ros"]["introspect"]
    assert set(ros["exit_codes"].values()) == {0}, ros["exit_codes"]
    assert ros["same_decisions"] == [True, True, True], ros["trials"]
    offline = result["policies"]["introspect"]["trials"]
    aborts = [d for t in offline for d in t["decisions"] if d["kind"] == "abort"]
    assert len(aborts) >= 2  # both failing worlds were aborted on an alarm
    assert ros["success_over_ros"] == ros["success_offline"]
    published = ros["samples"]["sim_node"][0]
    assert published > 0
    for node in ("segmenter_node", "verifier_node"):
        assert ros["samples"][node] == [published, 0], ros["samples"]  # none dropped


def _start(tmp_path: Path, env: dict[str, str]) -> dict[str, NodeProcess]:
    specs: list[tuple[str, type, dict[str, Any]]] = [
        ("sim_node", SimNodeConfig, {"rate_factor": 2.0}),
        ("segmenter_node", SegmenterConfig, {}),
        ("classifier_node", ClassifierConfig, {}),  # no model: it publishes 'unknown'
        ("verifier_node", VerifierConfig, {}),  # no verifier file: no verdicts
        ("planner_node", PlannerConfig, {"policy": "introspect"}),  # no verifier file
    ]
    return {
        name: NodeProcess(
            name,
            write_params(tmp_path / f"{name}.yaml", cls, values),
            env,
            tmp_path / f"{name}.log",
        )
        for name, cls, values in specs
    }


def test_bad_goals_are_rejected_and_sigint_mid_attempt_exits_0(tmp_path: Path) -> None:
    require_ros()
    from geometry_msgs.msg import WrenchStamped
    from rcbht_interfaces.action import Attempt
    from rcbht_interfaces.srv import RunTrial, StartTrial
    from rclpy.action.client import ActionClient

    from rcbht_introspection.rostools.session import RosSession

    domain = lease_domain()
    procs = _start(tmp_path, ros_env(domain, tmp_path / "ros_log"))
    every = list(procs.values())
    try:
        with RosSession("closed_loop_test", domain_id=domain) as ros:
            node = ros.node
            samples: list[Any] = []
            node.create_subscription(WrenchStamped, "/wrench", samples.append, 1000)
            start = node.create_client(StartTrial, "/sim_node/start_trial")
            run = node.create_client(RunTrial, "/planner_node/run_trial")
            action = ActionClient(node, Attempt, "/sim_node/attempt")

            def call(future: Any, what: str) -> Any:
                wait_for_nodes(future.done, 60.0, every, what)
                return future.result()

            # the action server too: a goal sent before its services are matched is lost
            wait_for_nodes(
                lambda: (
                    start.service_is_ready() and run.service_is_ready() and action.server_is_ready()
                ),
                120.0,
                every,
                "up",
            )
            early = call(action.send_goal_async(Attempt.Goal(attempt=1)), "a goal before a trial")
            assert call(early.get_result_async(), "its result").result.reason == "rejected"
            assert call(
                start.call_async(StartTrial.Request(seed=7, failure="jamming")), "trial"
            ).accepted
            for goal in (Attempt.Goal(dx=math.nan), Attempt.Goal(dyaw=1.0)):
                handle = call(action.send_goal_async(goal), "a bad goal")
                result = call(handle.get_result_async(), "its result").result
                assert result.reason == "rejected" and result.message, result
            assert samples == []  # no motion
            assert call(run.call_async(RunTrial.Request(trial=1)), "run").accepted
            wait_for_nodes(lambda: len(samples) > 400, 60.0, every, "the attempt's wrench")
            for p in every:  # mid-attempt
                p.interrupt()
            codes = {name: p.stop() for name, p in procs.items()}
    finally:
        for p in every:
            p.stop()
        release_domain(domain)
    assert codes == dict.fromkeys(procs, 0), {n: procs[n].tail() for n in procs}
    planner_log = (tmp_path / "planner_node.log").read_text()
    assert planner_log.count("no verifier file: policy introspect runs as retry") == 1

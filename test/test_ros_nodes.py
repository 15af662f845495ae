"""The nodes as separate processes over real DDS: ament index layout, parameters, robustness, SIGINT."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from ros_support import (
    answer,
    env,
    require_ros,
    ros_env,
    segmenter_inputs,
    start_node,
    wrench_msg,
)

from rcbht_introspection.replay.supervision import stop_process
from rcbht_introspection.waiting import wait_until

pytestmark = pytest.mark.ros
__all__ = ["env"]  # the isolated-ROS fixture, used by name


def test_ament_index_finds_the_executables(monkeypatch: pytest.MonkeyPatch) -> None:
    """`ros2 run` resolves <prefix>/lib/<package>/<executable> through the ament index."""
    require_ros()
    from ament_index_python.packages import get_package_prefix, get_package_share_directory

    monkeypatch.setenv("AMENT_PREFIX_PATH", sys.prefix)
    prefix = Path(get_package_prefix("rcbht_introspection"))
    for exe in ("segmenter_node", "classifier_node"):
        path = prefix / "lib" / "rcbht_introspection" / exe
        assert path.is_file() and os.access(path, os.X_OK), path
        assert path.read_text().startswith("#!")
    share = Path(get_package_share_directory("rcbht_introspection"))
    assert (share / "config" / "segmenter.yaml").is_file()
    assert (share / "config" / "classifier.yaml").is_file()
    assert (Path(get_package_share_directory("rcbht_interfaces")) / "msg" / "Words.msg").is_file()


def test_notes_of_every_level_log_through_one_helper() -> None:
    """rclpy fixes the severity of a logging call site at its first call and raises ValueError
    at another: a teaching classifier's info note, then a refusal's warning, from one shared
    call raised in the ~/teach callback and stopped the node (its service went unanswered)."""
    require_ros()
    from rclpy.logging import get_logger

    from rcbht_introspection.nodes.common import log_notes

    notes = [("info", "taught"), ("warning", "refused"), ("error", "failed"), ("info", "again")]
    logger = get_logger("notes_test")
    log_notes(logger, notes)
    log_notes(logger, notes[::-1])


@pytest.mark.parametrize("available", [True, False])
def test_the_events_executor_by_default_and_the_fallback(
    monkeypatch: pytest.MonkeyPatch, available: bool
) -> None:
    """`spin: events` gets rclpy's EventsExecutor, or the SingleThreadedExecutor where rclpy has
    none (its module made unimportable here); `spin: executor` the SingleThreadedExecutor."""
    require_ros()
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from rcbht_introspection.nodes.common import make_executor

    if not available:
        monkeypatch.setitem(sys.modules, "rclpy.experimental.events_executor", None)
    context = Context()
    rclpy.init(context=context)
    try:
        executor, events = make_executor("events", context)
        assert events == available
        assert isinstance(executor, SingleThreadedExecutor) != available
        assert type(executor).__name__ == (
            "EventsExecutor" if available else "SingleThreadedExecutor"
        )
        executor.shutdown()
        fallback, events = make_executor("executor", context)
        assert isinstance(fallback, SingleThreadedExecutor) and not events
        fallback.shutdown()
    finally:
        rclpy.shutdown(context=context)


def test_installed_executable_rejects_a_bad_parameter(tmp_path: Path) -> None:
    """Runs the installed lib/rcbht_introspection/classifier_node as `ros2 run` would."""
    require_ros()
    exe = Path(sys.prefix) / "lib" / "rcbht_introspection" / "classifier_node"
    env = ros_env(tmp_path)
    env["PATH"] = os.path.dirname(sys.executable) + os.pathsep + env.get("PATH", "")
    env.pop("PYTHONPATH", None)  # the installed copy
    proc = subprocess.run(
        [str(exe), "--ros-args", "-p", "mode:=psychic"],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2, proc.stderr
    errors = [line for line in proc.stderr.splitlines() if "error" in line]
    assert errors == [
        "[classifier_node] error: field mode: expected boundary or window, got 'psychic'"
    ]


def test_bad_segmenter_parameter_from_file(tmp_path: Path, env: dict[str, str]) -> None:
    params = tmp_path / "seg.yaml"
    params.write_text("segmenter_node:\n  ros__parameters:\n    arms: [L, R]\n")
    proc = subprocess.run(
        [sys.executable, "-m", "rcbht_introspection.nodes", "segmenter_node", "--ros-args",
         "--params-file", str(params)],
        env=env, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert proc.returncode == 2
    assert "field wrench_topics: expected one topic per arm (2), got 1" in proc.stderr


@pytest.mark.parametrize("model", ["missing", "garbage", "other_profile"])
def test_classifier_without_usable_model_says_unknown(
    tmp_path: Path, env: dict[str, str], model: str
) -> None:
    from std_msgs.msg import String

    from rcbht_introspection.rostools.session import RosSession

    path = tmp_path / "model.rcbht"
    params: dict[str, object] = {"model_file": str(path), "publish_rate_hz": 20.0}
    expect = str(path)
    if model == "garbage":
        path.write_text("this is not a model\n")
    if model == "other_profile":
        from rcbht_introspection.grammar.split import SubtaskSample
        from rcbht_introspection.learn.model_file import save_model
        from rcbht_introspection.learn.models import train_model
        from rcbht_introspection.taxonomy.words import Level, TrialWords, Word

        samples = []
        for i, (subtask, label) in enumerate([("approach", "bpos"), ("mating", "cons")] * 3):
            tw = TrialWords(name=f"t{i}")
            tw.add(Word("Fz", Level.PRIMITIVE, label, 0.0, 1.0 + i, arm="R"))
            samples.append(SubtaskSample(f"t{i}", subtask, 0.0, 1.0 + i, tw))
        save_model(train_model(samples), path)
        params["expected_profile"] = "error_charac"
        expect = "trained with taxonomy profile 'reference', the segmenter uses 'error_charac'"
    log = tmp_path / "classifier.log"
    proc = start_node("classifier_node", params, env, log)
    states: list[str] = []
    try:
        with RosSession("probe", domain_id=int(env["ROS_DOMAIN_ID"])) as ros:
            ros.node.create_subscription(String, "/task_state", lambda m: states.append(m.data), 10)
            assert wait_until(lambda: len(states) >= 3), log.read_text()
        assert set(states) == {"unknown"}
        assert proc.poll() is None
    finally:
        code = stop_process(proc, timeout=15)
    text = log.read_text()
    assert "no usable model" in text and expect in text
    assert code == 0, text


def test_segmenter_survives_malformed_input_and_sigint(tmp_path: Path, env: dict[str, str]) -> None:
    from rcbht_interfaces.msg import Words
    from std_msgs.msg import String

    from rcbht_introspection.nodes.common import qos_profile
    from rcbht_introspection.rostools.session import RosSession

    log = tmp_path / "segmenter.log"
    task = tmp_path / "task.yaml"  # names the sub-tasks: 'pirouette' below is not one of them
    task.write_text("subtasks: [approach, rotation, insertion, mating]\n")
    proc = start_node("segmenter_node", {"task_file": str(task)}, env, log)
    ends: list[Words] = []
    words = 0
    try:
        with RosSession("probe", domain_id=int(env["ROS_DOMAIN_ID"])) as ros:
            qos = qos_profile(1000, "reliable")

            def on_words(msg: Words) -> None:
                nonlocal words
                words += len(msg.words)
                if msg.end_of_stream:
                    ends.append(msg)

            ros.node.create_subscription(Words, "/rcbht/primitives", on_words, qos)
            wrench, phase = segmenter_inputs(ros, log)

            def send(stamp_ns: int, value: float) -> None:
                wrench.publish(wrench_msg(stamp_ns, value, 0.1 * value))
                time.sleep(0.0005)

            base = 1_700_000_000 * 10**9
            n = 800
            phase.publish(String(data="approach"))
            for i in range(n):
                send(base + i * 5_000_000, 10 * math.sin(i / 40) + (i > 400) * 5)
                if i == 300:
                    send(base + i * 5_000_000, float("nan"))  # NaN
                    send(0, 1.0)  # zero stamp
                    send(base + (i - 10) * 5_000_000, 1.0)  # decreasing stamp
                    phase.publish(String(data="pirouette"))  # unknown sub-task name
                if i == 400:
                    phase.publish(String(data="rotation"))
            phase.publish(String(data="done"))
            assert wait_until(lambda: bool(ends), 30), log.read_text()
        assert ends[0].samples_accepted == n
        assert ends[0].samples_rejected == 3
        assert words > 0
        assert proc.poll() is None  # still running after the bad input
    finally:
        code = stop_process(proc, timeout=15)
    text = log.read_text()
    assert "ignored unknown /task_phase name 'pirouette'" in text
    assert "dropped a wrench sample" in text
    assert code == 0, text


def test_a_late_subscriber_still_gets_the_applied_sub_task_events(
    tmp_path: Path, env: dict[str, str]
) -> None:
    """rcbht/phase is latched: a classifier that matches after an event was applied still sees it."""
    from rcbht_interfaces.msg import Phase
    from std_msgs.msg import String

    from rcbht_introspection.nodes.common import phase_qos
    from rcbht_introspection.rostools.session import RosSession

    log = tmp_path / "segmenter.log"
    proc = start_node("segmenter_node", {}, env, log)
    try:
        with RosSession("probe", domain_id=int(env["ROS_DOMAIN_ID"])) as ros:
            wrench, phase = segmenter_inputs(ros, log)
            phase.publish(String(data="approach"))
            for i in range(20):
                wrench.publish(wrench_msg(1_700_000_000 * 10**9 + i * 5_000_000, float(i)))
                time.sleep(0.005)
            time.sleep(1.0)  # the event was applied and published with nobody listening
            got: list[str] = []
            ros.node.create_subscription(
                Phase, "/rcbht/phase", lambda m: got.append(m.name), phase_qos("reliable")
            )
            assert wait_until(lambda: got == ["approach"], 10), (got, log.read_text())
    finally:
        assert stop_process(proc, timeout=15) == 0, log.read_text()


@pytest.mark.parametrize("spin", ["events", "executor"])
def test_a_busy_node_still_answers_parameter_requests(
    tmp_path: Path, env: dict[str, str], spin: str
) -> None:
    """Either executor serves the parameter services between the samples."""
    from geometry_msgs.msg import WrenchStamped
    from rclpy.parameter_client import AsyncParameterClient

    from rcbht_introspection.configure.params import SegmenterConfig, descriptions
    from rcbht_introspection.nodes.common import qos_profile
    from rcbht_introspection.rostools.session import RosSession

    log = tmp_path / "segmenter.log"
    proc = start_node("segmenter_node", {"event_hold_s": 0.3, "spin": spin}, env, log)
    try:
        with RosSession("probe", domain_id=int(env["ROS_DOMAIN_ID"])) as ros:
            client = AsyncParameterClient(ros.node, "segmenter_node")
            assert client.wait_for_services(20.0), log.read_text()
            wrench = ros.node.create_publisher(
                WrenchStamped, "/wrench", qos_profile(1000, "reliable")
            )
            assert wait_until(lambda: wrench.get_subscription_count() > 0), log.read_text()
            for i in range(400):  # keep the node busy while the requests come
                wrench.publish(wrench_msg(1_700_000_000 * 10**9 + i * 1_000_000, math.sin(i / 20)))
                if i % 100 == 50:
                    values = answer(lambda: client.get_parameters(["event_hold_s"]))
                    described = answer(lambda: client.describe_parameters(["event_hold_s"]))
                    assert values.values[0].double_value == 0.3
                    text = described.descriptors[0].description
                    assert text == descriptions(SegmenterConfig)["event_hold_s"]
                time.sleep(0.001)
    finally:
        assert stop_process(proc, timeout=15) == 0, log.read_text()

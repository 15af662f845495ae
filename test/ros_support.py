"""Test support for the ROS parts: availability checks, an isolated DDS environment, node processes.

Waiting and stopping use the package's own helpers (rcbht_introspection.waiting.wait_until,
rcbht_introspection.replay.supervision.stop_process), as the harness and benchmarks do."""

from __future__ import annotations

import importlib.util
import os
import time
from pathlib import Path

import pytest
from conftest import require

REPO = Path(__file__).resolve().parents[1]


def have(module: str) -> bool:
    """True when `module` can be imported (without importing it)."""
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


def require_ros() -> None:
    """rclpy and the built rcbht_interfaces must be present (CI: fail, locally: skip)."""
    require(have("rclpy"), "rclpy (ROS 2 Jazzy wheels) not installed")
    require(have("rcbht_interfaces"), "rcbht_interfaces not built (make setup builds msg_defs)")


def ros_env(tmp_path: Path) -> dict[str, str]:
    """Environment of an isolated ROS graph: a domain of its own, loopback only, logs in tmp.

    The domain is leased until the test ends (conftest releases it), so no two tests, nor a
    test and a replay or benchmark running beside it, share one.
    """
    from rcbht_introspection.replay.supervision import lease_domain
    from rcbht_introspection.replay.supervision import ros_env as env

    values = env(lease_domain(), tmp_path / "ros_log")
    full = {**os.environ, **values}
    full.pop("ROS_LOCALHOST_ONLY", None)
    full["PYTHONPATH"] = os.pathsep.join(
        p for p in (str(REPO), os.environ.get("PYTHONPATH", "")) if p
    )
    return full


def node_command(module: str, params: dict[str, object]) -> list[str]:
    """Command line of a node process with `-p name:=value` parameters."""
    import yaml

    from rcbht_introspection.replay.supervision import node_command as command

    args = []
    for name, value in params.items():
        text = yaml.safe_dump(value, default_flow_style=True).strip()
        text = text.removesuffix("\n...").removesuffix("...").strip()
        args += ["-p", f"{name}:={text}"]
    return command(module, *args)


def start_node(module: str, params: dict[str, object], env: dict[str, str], log: Path):
    """The node as a child process, its output in `log`."""
    import subprocess

    with log.open("w") as out:
        return subprocess.Popen(
            node_command(module, params), env=env, stdout=out, stderr=subprocess.STDOUT
        )


@pytest.fixture
def env(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> dict[str, str]:
    """Isolated ROS environment for the node processes and for this test process."""
    require_ros()
    values = ros_env(tmp_path)
    for key in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_LOG_DIR", "FASTRTPS_DEFAULT_PROFILES_FILE"):
        monkeypatch.setenv(key, values[key])
    monkeypatch.delenv("ROS_LOCALHOST_ONLY", raising=False)
    return values


def segmenter_inputs(ros, log: Path) -> tuple:
    """(/wrench, /task_phase) publishers of the probe, once the segmenter subscribes both."""
    from geometry_msgs.msg import WrenchStamped
    from std_msgs.msg import String

    from rcbht_introspection.nodes.common import qos_profile
    from rcbht_introspection.waiting import wait_until

    qos = qos_profile(1000, "reliable")
    wrench = ros.node.create_publisher(WrenchStamped, "/wrench", qos)
    phase = ros.node.create_publisher(String, "/task_phase", qos)
    assert wait_until(
        lambda: wrench.get_subscription_count() > 0 and phase.get_subscription_count() > 0
    ), log.read_text()
    return wrench, phase


def wrench_msg(stamp_ns: int, fz: float, mx: float = 0.0):
    """A WrenchStamped with force z and torque x."""
    from geometry_msgs.msg import WrenchStamped

    from rcbht_introspection.messages import to_time

    msg = WrenchStamped()
    msg.header.stamp = to_time(stamp_ns)
    msg.wrench.force.z = fz
    msg.wrench.torque.x = mx
    return msg


def answer(send, timeout: float = 20.0, attempt: float = 3.0):
    """The response to an idempotent service request, sent again while none arrives.

    `wait_for_service` only says the server was discovered, not that its response writer has
    matched our response reader; Fast DDS waits 100 ms for that match and otherwise drops the
    response (ros2/rmw_fastrtps#390, #467), which happens on a loaded machine. The request is
    therefore repeated every `attempt` seconds, as a ROS lifecycle manager would."""
    from rcbht_introspection.waiting import wait_until

    futures = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        futures.append(send())
        left = deadline - time.monotonic()
        if wait_until(lambda: any(f.done() for f in futures), max(0.0, min(attempt, left))):
            return next(f for f in futures if f.done()).result()
    raise AssertionError(f"no response in {timeout} s to {len(futures)} requests")

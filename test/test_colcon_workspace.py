"""The repository built and started as a ROS workspace does it: a copy in ws/src, `colcon build`
(the pinned colcon-core and colcon-ros, both packages: msg_defs' rcbht_interfaces and the
ament_python package), `source install/setup.sh`, the node executables where `ros2 run` finds
them (the ament index: <prefix>/lib/rcbht_introspection/<node>), a bag played to them and
/task_state read."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import require
from ros_support import REPO, have, require_ros, ros_env

from rcbht_introspection.replay.supervision import stop_process
from rcbht_introspection.waiting import wait_until

pytestmark = [pytest.mark.ros, pytest.mark.slow]

COPY_IGNORE = shutil.ignore_patterns(
    ".git", ".venv", "build", "install", "log", "bench_out", "demo_out", "__pycache__",
    "*.egg-info", ".mypy_cache", ".ruff_cache", ".pytest_cache",
)  # fmt: skip
"""What a clone would not hold (set-up products, caches)."""


def build_env() -> dict[str, str]:
    """The environment of a shell with the ROS 2 wheels' prefix as underlay (what
    `source /opt/ros/jazzy/setup.bash` gives on a ROS install): this venv's python first."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    bin_dir = str(Path(sys.executable).parent)
    env["PATH"] = os.pathsep.join([bin_dir, env.get("PATH", "")])
    env["AMENT_PREFIX_PATH"] = sys.prefix
    env["CMAKE_PREFIX_PATH"] = sys.prefix
    return env


def sourced(ws: Path, command: str) -> list[str]:
    """`command` in bash after `source install/setup.sh` of `ws` (the pinned colcon has no
    colcon-bash, which writes setup.bash on a ROS install; setup.sh sets the same variables)."""
    return ["bash", "-c", f"source {ws / 'install' / 'setup.sh'} && {command}"]


def colcon_build(ws: Path) -> None:
    """colcon build of ws/src, as docs/install.md says: colcon does not look for packages inside a
    package, so msg_defs/ is named as a base path too (BUILD_TESTING off: no test dependencies)."""
    colcon = Path(sys.executable).parent / "colcon"
    result = subprocess.run(
        [
            str(colcon), "build", "--base-paths", "src", "src/rcbht_introspection/msg_defs",
            "--cmake-args", f"-DPython3_EXECUTABLE={sys.executable}", "-DBUILD_TESTING=OFF",
        ],
        cwd=ws, env=build_env(), capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    logs = "\n".join(
        p.read_text()[-3000:] for p in sorted(ws.glob("log/latest_build/*/stderr.log"))
    )
    assert result.returncode == 0, f"{result.stdout[-3000:]}\n{result.stderr[-3000:]}\n{logs}"


def small_model(work: Path) -> Path:
    """A sub-task model trained on three synthetic contact trials (seconds)."""
    from rcbht_introspection.bench.ros import synthetic_trial
    from rcbht_introspection.io.hiro import write_trial
    from rcbht_introspection.learn.data import load_trials
    from rcbht_introspection.learn.live import live_training
    from rcbht_introspection.learn.model_file import save_model

    folders = [write_trial(synthetic_trial(f"t-{i}", 20.0, i), work / f"t-{i}") for i in range(3)]
    model, _ = live_training(load_trials(folders, "auto"))
    return save_model(model, work / "model.rcbht")


def test_colcon_workspace_builds_and_runs_the_nodes(tmp_path: Path) -> None:
    """colcon build; the sourced workspace's own packages are the ones found; segmenter_node and
    classifier_node started from <prefix>/lib/rcbht_introspection/ take a played bag and publish
    /task_state values of the model's sub-tasks."""
    require_ros()
    require(have("colcon_core") and have("colcon_ros"), "colcon-core / colcon-ros not installed")
    require(shutil.which("cmake") is not None, "cmake not installed")
    ws = tmp_path / "ws"
    shutil.copytree(REPO, ws / "src" / "rcbht_introspection", ignore=COPY_IGNORE)
    colcon_build(ws)
    probe = (
        "python -c 'import rcbht_introspection, rcbht_interfaces; "
        "from ament_index_python.packages import get_package_prefix as p; "
        'print(p("rcbht_introspection"), p("rcbht_interfaces"), '
        "rcbht_introspection.__file__, rcbht_interfaces.__file__)'"
    )
    found = subprocess.run(
        sourced(ws, probe), cwd=ws, env=build_env(), capture_output=True, text=True, check=True
    ).stdout.split()
    assert all(p.startswith(str(ws / "install")) for p in found), found
    _play_to_the_installed_nodes(ws, Path(found[0]), tmp_path)


def _play_to_the_installed_nodes(ws: Path, prefix: Path, tmp_path: Path) -> None:
    from rcbht_interfaces.msg import Belief
    from std_msgs.msg import String

    from rcbht_introspection.bench.ros import synthetic_trial
    from rcbht_introspection.io.bags import write_trial_bag
    from rcbht_introspection.rostools.session import RosSession

    model = small_model(tmp_path / "train")
    write_trial_bag(synthetic_trial("played", 20.0, 7), tmp_path / "played.mcap")
    env = {**build_env(), **{k: v for k, v in ros_env(tmp_path).items() if k.startswith("ROS")}}
    exe = prefix / "lib" / "rcbht_introspection"
    nodes = {
        name: subprocess.Popen(
            sourced(ws, f"exec {exe / name} --ros-args {args}"),
            cwd=ws, env=env, stdout=(tmp_path / f"{name}.log").open("w"), stderr=subprocess.STDOUT,
        )
        for name, args in (
            ("segmenter_node", ""),
            ("classifier_node", f"-p model_file:={model} -p publish_rate_hz:=20.0"),
        )
    }  # fmt: skip
    states: list[str] = []
    beliefs: list[Belief] = []
    try:
        with RosSession("probe", domain_id=int(env["ROS_DOMAIN_ID"])) as ros:
            ros.node.create_subscription(
                String, "/task_state", lambda m: states.append(m.data), 100
            )
            ros.node.create_subscription(Belief, "rcbht/belief", beliefs.append, 10000)
            assert wait_until(lambda: bool(states), timeout=60), _logs(tmp_path)
            time.sleep(2.0)  # the segmenter's and the player's readers match each other
            play = "python -m rcbht_introspection.cli bag replay"
            subprocess.run(
                sourced(ws, f"{play} {tmp_path / 'played.mcap'} --rate 5 --wait 10"),
                cwd=ws, env=env, check=True, timeout=120,
            )  # fmt: skip
            assert wait_until(lambda: any(b.final for b in beliefs), timeout=30), _logs(tmp_path)
        classes = set(beliefs[-1].classes)
        assert sum(b.n_words > 0 for b in beliefs) > 10, _logs(tmp_path)
        assert set(states) <= classes | {"unknown"}, states
    finally:
        codes = {name: stop_process(proc, timeout=15) for name, proc in nodes.items()}
    assert codes == {name: 0 for name in nodes}, (codes, _logs(tmp_path))


def _logs(tmp_path: Path) -> str:
    return "\n".join(p.read_text()[-2000:] for p in sorted(tmp_path.glob("*_node.log")))

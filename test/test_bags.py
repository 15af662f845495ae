"""Trial bags: round trips through .mcap, .db3 and bag directories; CLI conversion; bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import SOURCES, require, trial_folders
from hypothesis import given
from hypothesis import strategies as st
from ros_support import have

from rcbht_introspection.cli import main
from rcbht_introspection.errors import InputError
from rcbht_introspection.io.bags import decode_wrench, decode_wrench_sample, encode_wrench
from rcbht_introspection.io.trial import Trial

pytestmark = pytest.mark.ros


@pytest.fixture(autouse=True)
def _rosbags() -> None:
    require(have("rosbags"), "rosbags not installed")


def two_arm_trial() -> Trial:
    """A synthetic two-arm trial with off-grid state times and non-trivial values."""
    rng = np.random.default_rng(3)
    t = np.round(np.arange(0, 3.0, 0.005), 6)
    return Trial(
        name="two-arm",
        time=t,
        wrench={"L": rng.normal(size=(len(t), 6)), "R": rng.normal(size=(len(t), 6)) * 10},
        state_times=(0.0, 0.7, 1.4031, 2.2),
        outcome="jam",
    )


@pytest.mark.parametrize("suffix", [".mcap", ".db3", ""])
def test_round_trip_two_arms(tmp_path: Path, suffix: str) -> None:
    from rcbht_introspection.io.bags import bag_messages, is_bag, read_trial_bag, write_trial_bag

    trial = two_arm_trial()
    path = tmp_path / f"trial{suffix}"
    write_trial_bag(trial, path)
    assert is_bag(path)
    back = read_trial_bag(path)
    assert back.name == "two-arm" and back.outcome == "jam"
    assert back.arms == ("L", "R")
    np.testing.assert_array_equal(back.time, trial.time)
    for arm in trial.arms:
        np.testing.assert_array_equal(back.wrench[arm], trial.wrench[arm])
    np.testing.assert_allclose(back.state_times, trial.state_times, atol=1e-9)
    topics = {m.topic for m in bag_messages(path)}
    assert {"/L/wrench", "/R/wrench", "/task_phase"} <= topics
    phases = [m for m in bag_messages(path) if m.topic == "/task_phase"]
    assert len(phases) == 5  # four sub-task starts and the end event


@pytest.mark.parametrize("suffix", [".mcap", ".db3"])
@pytest.mark.parametrize("source", SOURCES)
def test_hiro_trial_through_cli(
    request: pytest.FixtureRequest, tmp_path: Path, source: str, suffix: str
) -> None:
    """A trial folder in the HIRO layout (REAL S-05 or a generated one) survives `bag from-hiro`."""
    from rcbht_introspection.io.bags import read_trial_bag
    from rcbht_introspection.io.hiro import read_trial

    (folder,) = trial_folders(request, source, ["20121127-HIROSA-S-05"], [4])
    out = tmp_path / f"trial{suffix}"
    assert main(["bag", "from-hiro", str(folder), str(out)]) == 0
    trial, back = read_trial(folder), read_trial_bag(out)
    assert back.name == trial.name
    np.testing.assert_array_equal(back.time, trial.time)
    np.testing.assert_array_equal(back.wrench["R"], trial.wrench["R"])
    assert back.state_times == trial.state_times


def test_wrench_topic_names_and_single_arm(tmp_path: Path) -> None:
    from rcbht_introspection.io.bags import bag_messages, read_trial_bag, write_trial_bag

    t = np.arange(0, 1, 0.01)
    trial = Trial("one", t, {"R": np.ones((len(t), 6))}, state_times=(0.0, 0.5))
    write_trial_bag(trial, tmp_path / "one.mcap")
    assert {m.topic for m in bag_messages(tmp_path / "one.mcap")} == {
        "/wrench",
        "/task_phase",
        "/rcbht/trial_info",
    }
    back = read_trial_bag(tmp_path / "one.mcap")
    assert back.arms == ("R",) and back.state_times == (0.0, 0.5)


def test_bad_inputs(tmp_path: Path) -> None:
    from rcbht_introspection.io.bags import is_bag, read_trial_bag, write_trial_bag

    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not a bag at all")
    with pytest.raises(InputError, match=r"junk\.mcap"):
        read_trial_bag(junk)
    assert not is_bag(tmp_path / "missing.db3")
    with pytest.raises(InputError, match="not a rosbag2 bag"):
        read_trial_bag(tmp_path / "missing.db3")
    t = np.arange(0, 1, 0.01)
    trial = Trial("x", t, {"R": np.zeros((len(t), 6))})
    write_trial_bag(trial, tmp_path / "x.db3")
    with pytest.raises(InputError, match=r"exists already"):
        write_trial_bag(trial, tmp_path / "x.db3")
    assert main(["bag", "info", str(junk)]) == 2


def test_record_a_replay_between_processes(tmp_path: Path) -> None:
    """`rcbht bag replay` and `rcbht bag record` as separate processes over real DDS."""
    import subprocess
    import sys

    from ros_support import require_ros, ros_env

    from rcbht_introspection.io.bags import read_trial_bag, write_trial_bag
    from rcbht_introspection.replay.supervision import stop_process

    require_ros()
    env = ros_env(tmp_path)
    t = np.round(np.arange(0, 2.0, 0.005), 6)
    rng = np.random.default_rng(5)
    trial = Trial("rec", t, {"R": rng.normal(size=(len(t), 6))}, state_times=(0.0, 0.5, 0.9, 1.2))
    write_trial_bag(trial, tmp_path / "src.db3")
    cli = [sys.executable, "-m", "rcbht_introspection.cli", "bag"]
    rec_log = (tmp_path / "record.log").open("w")
    recorder = subprocess.Popen(
        [*cli, "record", "/wrench", "/task_phase", "--out", str(tmp_path / "rec.mcap")],
        env=env, stdout=rec_log, stderr=subprocess.STDOUT,
    )  # fmt: skip
    try:
        play = subprocess.run(
            [*cli, "replay", str(tmp_path / "src.db3"), "--rate", "4", "--wait", "20"],
            env=env, capture_output=True, text=True, timeout=120,
        )  # fmt: skip
        assert play.returncode == 0, play.stderr
        assert "published 406 messages" in play.stdout  # 400 samples, 5 events, 1 info record
        # the player waited for the recorder's acknowledgments; the recorder settles at stop
    finally:
        code = stop_process(recorder, timeout=15)
    rec_log.close()
    assert code == 0, (tmp_path / "record.log").read_text()
    back = read_trial_bag(tmp_path / "rec.mcap")
    np.testing.assert_array_equal(back.wrench["R"], trial.wrench["R"])
    np.testing.assert_array_equal(back.time, trial.time)
    assert back.state_times == trial.state_times


@pytest.mark.parametrize("source", SOURCES)
def test_train_accepts_bags(request: pytest.FixtureRequest, tmp_path: Path, source: str) -> None:
    from rcbht_introspection.learn.model_file import load_model

    names = [f"20121127-HIROSA-S-{i:02d}" for i in (1, 2, 3)]
    for i, folder in enumerate(trial_folders(request, source, names, [0, 1, 2])):
        assert main(["bag", "from-hiro", str(folder), str(tmp_path / "bags" / f"{i}.db3")]) == 0
    model = tmp_path / "model.rcbht"
    assert main(["train", str(tmp_path / "bags"), "--out", str(model)]) == 0
    assert sorted(load_model(model).classes_) == ["approach", "insertion", "mating", "rotation"]


@given(
    stamp=st.integers(1, 2**31 * 10**9 - 1),
    frame=st.text(st.characters(min_codepoint=33, max_codepoint=0x2FF), max_size=20),
    values=st.tuples(*[st.floats(allow_nan=False)] * 6),
)
def test_wrench_cdr_round_trips(stamp: int, frame: str, values: tuple[float, ...]) -> None:
    """The live decoder (no frame) and the bag decoder read what encode_wrench writes; rclpy's
    own bytes are checked against both in test_bench_soak (needs the ROS wheels)."""
    raw = encode_wrench(stamp, frame, values)
    assert decode_wrench(raw) == (stamp, frame, values)
    assert decode_wrench_sample(raw) == (stamp, values)

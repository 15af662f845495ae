"""Simulator: determinism, sub-task structure, failure labels, two-arm output, CLI layout, and the
contact signature of the wrench (force build-up and snap-through drop during insertion)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from rcbht_introspection.cli import main as cli_main
from rcbht_introspection.errors import InputError
from rcbht_introspection.io.hiro import read_trial
from rcbht_introspection.io.trial import SUBTASKS, Trial
from rcbht_introspection.sim import SimConfig, load_sim_config, simulate_trial, write_dataset


@pytest.fixture(scope="module")
def config() -> SimConfig:
    return load_sim_config()


@pytest.fixture(scope="module")
def successes(config: SimConfig) -> list[Trial]:
    return [simulate_trial(config, seed) for seed in (11, 12, 300)]


def _phase(trial: Trial, name: str, arm: str = "R") -> np.ndarray:
    for subtask, start, end in trial.subtask_bounds():
        if subtask == name:
            mask = (trial.time >= start) & (trial.time < end)
            return trial.wrench[arm][mask]
    raise AssertionError(f"{trial.name} has no {name} sub-task")


def test_yaml_config_matches_the_dataclass_defaults(config: SimConfig) -> None:
    assert config == SimConfig()


def test_bad_config_key_is_a_one_line_error(tmp_path: Path) -> None:
    bad = tmp_path / "sim.yaml"
    bad.write_text("physics:\n  timestep: 0.001\n  stifness: 3\n")
    with pytest.raises(InputError, match=r"physics\.stifness"):
        load_sim_config(bad)


def test_same_seed_same_trial_other_seed_other_trial(
    config: SimConfig, successes: list[Trial]
) -> None:
    again = simulate_trial(config, 11)
    first = successes[0]
    assert again.state_times == first.state_times
    np.testing.assert_array_equal(again.wrench["R"], first.wrench["R"])
    other = successes[1]
    assert other.state_times != first.state_times
    assert not np.array_equal(other.wrench["R"][:500], first.wrench["R"][:500])


def test_success_trials_have_four_subtasks_in_order(successes: list[Trial]) -> None:
    for trial in successes:
        assert trial.outcome == "success" and trial.metadata["latched"] is True
        assert len(trial.state_times) == len(SUBTASKS) and trial.state_times[0] == 0.0
        bounds = [*trial.state_times, trial.end_time]
        durations = np.diff(bounds)
        assert (durations > 0.5).all(), (trial.name, durations)
        assert 15.0 < trial.end_time < 60.0  # real HIRO successes last 22-34 s (one 84 s)
        np.testing.assert_allclose(np.diff(trial.time), 0.005, atol=1e-9)


def test_wrench_shows_contact_build_up_and_snap_through(successes: list[Trial]) -> None:
    for trial in successes:
        approach = _phase(trial, "approach")
        free = approach[: len(approach) // 2, 2]
        assert abs(free.mean()) < 1.0 and free.std() < 0.3  # no contact: noise and bias only
        fz = _phase(trial, "insertion")[:, 2]
        running_peak = np.maximum.accumulate(fz)
        built_up = running_peak > 12.0  # force build-up against the snap hooks
        assert built_up.any(), trial.name
        drop = (running_peak - fz)[built_up] / running_peak[built_up]
        assert drop.max() > 0.4, trial.name  # snap-through: the force falls well below its peak
        mating = _phase(trial, "mating")[:, 2]
        assert mating.max() > 15.0  # held against the seat


@pytest.mark.parametrize("failure", ["misalignment", "jamming", "missed_snap"])
def test_failure_trials_carry_their_label(config: SimConfig, failure: str) -> None:
    trial = simulate_trial(config, 5, failure=failure)
    assert trial.outcome == failure
    assert trial.metadata["latched"] is False and trial.metadata["requested"] == failure
    if failure == "missed_snap":
        assert len(trial.state_times) == 4  # the controller believed it was done
    else:
        assert len(trial.state_times) == 3 and trial.metadata["aborted"] is True
        assert _phase(trial, "insertion")[:, 2].max() > 30.0  # pushing against the obstacle


def test_two_arm_writes_both_arms(tmp_path: Path) -> None:
    (folder,) = write_dataset(tmp_path, 1, scenario="two-arm", seed=3)
    assert (folder / "L_Torques.dat").is_file() and (folder / "R_Torques.dat").is_file()
    trial = read_trial(folder)
    assert trial.arms == ("L", "R") and len(trial.state_times) == 4
    # the holding arm feels the insertion push too
    assert _phase(trial, "insertion", "L")[:, 2].max() > 10.0


def test_cli_writes_the_hiro_layout(tmp_path: Path) -> None:
    out = tmp_path / "D"
    code = cli_main(
        [
            "sim",
            "--trials",
            "3",
            "--seed",
            "2",
            "--failures",
            "--out",
            str(out),
            "--progress",
            "off",
        ]
    )
    assert code == 0
    folders = sorted(p for p in out.iterdir() if p.is_dir())
    expected = ["SIM-ONE-F-02-misalignment", "SIM-ONE-S-01", "SIM-ONE-S-03"]
    assert [p.name for p in folders] == expected
    for folder in folders:
        trial = read_trial(folder)
        meta = json.loads((folder / "meta.json").read_text())
        assert trial.outcome == ("misalignment" if "-F-" in folder.name else "success")
        assert meta["seed"] >= 2000
        assert not (folder / "L_Torques.dat").exists()
    index = json.loads((out / "sim_meta.json").read_text())
    assert [t["outcome"] for t in index["trials"]] == ["success", "misalignment", "success"]


def test_1khz_output_and_bad_rate(
    config: SimConfig, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    trial = simulate_trial(config, 11, rate_hz=1000.0)
    np.testing.assert_allclose(np.diff(trial.time[:100]), 0.001, atol=1e-9)
    assert cli_main(["sim", "--trials", "1", "--rate", "300", "--out", str(tmp_path)]) == 2
    assert "300 Hz does not divide" in capsys.readouterr().err


def test_bag_format(tmp_path: Path) -> None:
    if importlib.util.find_spec("rcbht_introspection.io.bags") is None:
        with pytest.raises(InputError, match="--format hiro"):
            write_dataset(tmp_path, 1, fmt="bag")
    else:
        from rcbht_introspection.io.bags import read_trial_bag

        (path,) = write_dataset(tmp_path, 1, seed=4, fmt="bag")
        back = read_trial_bag(path)
        assert path.suffix == ".mcap" and back.arms == ("R",)
        assert len(back.state_times) == 4 and back.outcome == "success"
        assert back.end_time > 15.0


def test_rerun_replaces_the_previous_set_and_refuses_foreign_data(tmp_path: Path) -> None:
    write_dataset(tmp_path, 2, seed=1)
    write_dataset(tmp_path, 1, seed=1)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["SIM-ONE-S-01", "sim_meta.json"]
    foreign = tmp_path / "other"
    (foreign / "real").mkdir(parents=True)
    (foreign / "real" / "R_Torques.dat").write_text("0 0 0 0 0 0 0\n")
    with pytest.raises(InputError, match="did not write"):
        write_dataset(foreign, 1)

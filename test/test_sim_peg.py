"""The peg-in-hole task of the simulator: its own phases and task file, the task through folders
and bags into learn.data, determinism, learnable words, and the noisy 100 Hz sensor (on which the
default RCBHT thresholds cut nearly every window)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from rcbht_introspection.cli import main as cli_main
from rcbht_introspection.commands.sim import TASK_CHOICES
from rcbht_introspection.errors import InputError
from rcbht_introspection.io.bags import read_trial_bag, write_trial_bag
from rcbht_introspection.io.hiro import read_trial
from rcbht_introspection.learn.data import load_trials
from rcbht_introspection.learn.evaluate import trial_kfold_accuracy
from rcbht_introspection.sim import (
    PEG_TASK,
    SIM_TASKS,
    PegConfig,
    load_peg_config,
    load_sim_config,
    simulate_peg_trial,
    write_dataset,
)
from rcbht_introspection.task import HIRO_TASK, TASK_FILE, load_task_file
from rcbht_introspection.taxonomy.batch import label_trial
from rcbht_introspection.taxonomy.config import default_config
from rcbht_introspection.taxonomy.words import AXES, Level

N_TRIALS = 8


@pytest.fixture(scope="module")
def config() -> PegConfig:
    return load_peg_config()


@pytest.fixture(scope="module")
def peg_set(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """A small peg-in-hole set in the HIRO layout (task.yaml beside each trial)."""
    out = tmp_path_factory.mktemp("peg")
    return write_dataset(out, N_TRIALS, seed=3, task="peg-in-hole")


def test_phases_are_the_peg_tasks_own_in_order(peg_set: list[Path], config: PegConfig) -> None:
    assert not set(PEG_TASK.subtasks) & set(HIRO_TASK.subtasks)
    assert 3 <= len(PEG_TASK.subtasks) <= 5
    for folder in peg_set:
        assert folder.name.startswith("SIM-PEG-S-")
        trial = read_trial(folder)
        assert trial.outcome == "success"
        assert trial.phases == PEG_TASK.subtasks and trial.state_times[0] == 0.0
        durations = np.diff([*trial.state_times, trial.end_time])
        assert (durations > 0.3).all(), (folder.name, durations)  # every phase really happens
        assert load_task_file(folder / TASK_FILE) == PEG_TASK


def test_trial_folders_load_as_complete_peg_trials(peg_set: list[Path]) -> None:
    trials = load_trials(peg_set, words="engine")
    assert len(trials) == N_TRIALS
    for t in trials:
        assert t.task == PEG_TASK and t.complete
        assert [s.subtask for s in t.samples] == list(PEG_TASK.subtasks)


def test_bags_carry_the_task(tmp_path: Path, peg_set: list[Path]) -> None:
    (bag,) = write_dataset(tmp_path / "bags", 1, seed=5, task="peg-in-hole", fmt="bag")
    back = read_trial_bag(bag)
    assert back.metadata["task"] == PEG_TASK.to_dict()
    assert back.phases == PEG_TASK.subtasks
    # a bag converted from a trial folder keeps the task too (read_trial reads task.yaml)
    converted = tmp_path / "converted.mcap"
    write_trial_bag(read_trial(peg_set[0]), converted)
    for path in (bag, converted):
        (loaded,) = load_trials([path], words="engine")
        assert loaded.task == PEG_TASK and loaded.complete


def test_same_seed_same_trial_other_seed_other_trial(config: PegConfig) -> None:
    first, again, other = (simulate_peg_trial(config, s) for s in (21, 21, 22))
    assert again.state_times == first.state_times
    np.testing.assert_array_equal(again.wrench["R"], first.wrench["R"])
    assert other.state_times != first.state_times
    assert not np.array_equal(other.wrench["R"][:100], first.wrench["R"][:100])


def test_words_separate_the_phases_better_than_their_durations(peg_set: list[Path]) -> None:
    result = trial_kfold_accuracy(peg_set[0].parent)
    assert result["available"] and result["samples"] == 4 * N_TRIALS
    accuracy, by_duration = float(result["accuracy"]), float(result["duration_accuracy"])
    assert accuracy >= 0.8 and accuracy > by_duration + 0.2, result


def _white_noise(wrench: np.ndarray, n: int) -> np.ndarray:
    """Std per axis of the sample-to-sample differences / sqrt 2 over the first n samples (in free
    space): the white noise; the slow disturbances hardly count at this lag."""
    return np.diff(wrench[:n], axis=0).std(axis=0) / np.sqrt(2)


@pytest.mark.parametrize(
    "changed", [{}, {"rate_hz": 50.0, "noise_force": 0.3, "quantization_force": 0.05}]
)
def test_sensor_rate_quantisation_and_noise_are_the_configs(
    config: PegConfig, changed: dict[str, float]
) -> None:
    sensor = dataclasses.replace(config.sensor, **changed)
    cfg = dataclasses.replace(config, sensor=sensor)
    trial = simulate_peg_trial(cfg, 4)
    np.testing.assert_allclose(np.diff(trial.time), 1.0 / sensor.rate_hz, atol=1e-9)
    assert trial.metadata["rate_hz"] == sensor.rate_hz
    forces, torques = trial.wrench["R"][:, :3], trial.wrench["R"][:, 3:]
    for values, q in ((forces, sensor.quantization_force), (torques, sensor.quantization_torque)):
        np.testing.assert_allclose(values / q, np.round(values / q), atol=1e-6)
    free = int((trial.state_times[1] - 0.2) * sensor.rate_hz)  # before the contact at its end
    noise = _white_noise(trial.wrench["R"], free)
    scale = float(trial.metadata["noise_scale"])
    np.testing.assert_allclose(noise[:3] / (sensor.noise_force * scale), 1.0, atol=0.3)
    np.testing.assert_allclose(noise[3:] / (sensor.noise_torque * scale), 1.0, atol=0.3)


def test_default_thresholds_cut_nearly_every_window(peg_set: list[Path]) -> None:
    """On this sensor the default fit threshold closes a primitive at most window steps: the
    degenerate case a calibration has to fix."""
    window = default_config().window
    trial = read_trial(peg_set[0])
    words = label_trial(trial)
    steps = (len(trial.time) - 1) // window
    per_step = [len(words.words["R"][Level.PRIMITIVE][axis]) / steps for axis in AXES]
    assert np.mean(per_step) > 0.6, per_step


def test_cli_task_option(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert TASK_CHOICES == SIM_TASKS
    out = tmp_path / "P"
    args = ["sim", "--task", "peg-in-hole", "--trials", "1", "--out", str(out)]
    assert cli_main([*args, "--progress", "off"]) == 0
    assert (out / "SIM-PEG-S-01" / TASK_FILE).is_file()
    assert "peg-in-hole" in capsys.readouterr().out
    failing = tmp_path / "F"
    two = ["sim", "--task", "peg-in-hole", "--trials", "2", "--failures", "--progress", "off"]
    assert cli_main([*two, "--out", str(failing)]) == 0
    assert (failing / "SIM-PEG-F-02-hole_yaw").is_dir()
    assert cli_main([*args, "--scenario", "two-arm"]) == 2
    assert "no scenario 'two-arm'" in capsys.readouterr().err


def test_snap_config_is_refused_for_the_peg_task(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="does not configure task peg-in-hole"):
        write_dataset(tmp_path, 1, task="peg-in-hole", config=load_sim_config())


def test_realism_report_refuses_a_peg_set(
    peg_set: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """sim-report compares with HIRO's four sub-tasks: a peg set is named, not half-compared."""
    real = tmp_path / "real"
    real.mkdir()
    args = ["sim-report", str(peg_set[0].parent), "--real", str(real), "--out", str(tmp_path)]
    assert cli_main(args) == 2
    assert "holds peg-in-hole trials" in capsys.readouterr().err

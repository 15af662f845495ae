"""Tasks from the data: sub-task names from phase events, task files and model files."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import SIM_SUCCESS

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.bags import read_trial_bag, write_trial_bag
from rcbht_introspection.io.hiro import find_trials, read_trial, write_trial
from rcbht_introspection.io.trial import Trial, check_phases
from rcbht_introspection.learn.data import load_trial_samples, load_trials, task_of_trials
from rcbht_introspection.learn.model_file import load_model, load_subtask_model, save_model
from rcbht_introspection.learn.models import train_model
from rcbht_introspection.task import (
    HIRO_TASK,
    Task,
    load_task_file,
    task_from_sequences,
    task_of_names,
)

PICK = ("reach", "grasp", "lift", "place", "release")


def test_order_of_sub_tasks_comes_from_the_sequences() -> None:
    """Skipped and repeated sub-tasks keep the others' order; the end phase ends a sequence."""
    task = task_from_sequences(
        [["reach", "lift", "done", "late"], ["reach", "grasp", "lift"], ["grasp", "grasp", "place"]]
    )
    assert task.subtasks == ("reach", "grasp", "lift", "place")
    # contradicting orders: the name seen first comes first
    assert task_from_sequences([["a", "b"], ["b", "a"]]).subtasks == ("a", "b")
    assert task_of_names([["approach", "rotation"]]) == HIRO_TASK  # old data: HIRO's task
    with pytest.raises(InputError, match="no sub-task names"):
        task_from_sequences([["done"]])


def test_task_file_errors_name_file_line_and_field(tmp_path: Path) -> None:
    good = tmp_path / "task.yaml"
    good.write_text("name: pick\nsubtasks: [reach, grasp]\nend_phases: [done, abort]\n")
    assert load_task_file(good) == Task(("reach", "grasp"), ("done", "abort"), "pick")
    bad = tmp_path / "bad.yaml"
    bad.write_text("subtasks: [reach, grasp]\nend_phases: [grasp]\n")
    with pytest.raises(InputError) as err:
        load_task_file(bad)
    assert str(err.value).startswith(f"{bad}, line 2, field end_phases: ['grasp'] named both")


def _pick_trial(seed: int, phases: tuple[str, ...] = PICK) -> Trial:
    """A synthetic one-arm trial: each phase a different force level and slope, 200 Hz, noise."""
    rng = np.random.default_rng(seed)
    durations = rng.uniform(0.8, 1.6, len(phases))
    starts = np.concatenate([[0.0], np.cumsum(durations)[:-1]])
    time = np.arange(0.0, float(durations.sum()), 0.005)
    wrench = rng.normal(0, 0.02, (len(time), 6))
    for i, start in enumerate(starts):
        inside = time >= start
        level = PICK.index(phases[i]) + 1.0
        wrench[inside, 2] = level * 3 + (time[inside] - start) * (-1) ** i * 4
        wrench[inside, 3] = level * 0.2
    return Trial(f"pick-{seed:02d}", time, {"R": wrench}, tuple(map(float, starts)), phases=phases)


def test_bag_round_trip_keeps_any_names_and_repeats(tmp_path: Path) -> None:
    repeated = ("reach", "grasp", "reach", "grasp", "lift")
    trial = _pick_trial(1, repeated)
    write_trial_bag(trial, tmp_path / "t.mcap")
    back = read_trial_bag(tmp_path / "t.mcap")
    assert back.phases == repeated
    np.testing.assert_allclose(back.state_times, trial.state_times, atol=1e-9)
    samples = load_trial_samples(tmp_path / "t.mcap").samples
    assert [s.subtask for s in samples] == list(repeated)  # a repeat is another sample


def test_a_trial_folder_keeps_its_task_and_refuses_repeats(tmp_path: Path) -> None:
    """write_trial stores the task the trial carries; a repeated sub-task needs a bag."""
    trial = _pick_trial(3)
    task = Task(PICK, ("finished",), "pick")
    write_trial(replace(trial, metadata={"task": task.to_dict()}), tmp_path / "a")
    assert load_task_file(tmp_path / "a" / "task.yaml") == task
    with pytest.raises(InputError, match="cannot repeat a sub-task"):
        write_trial(_pick_trial(4, ("reach", "grasp", "reach")), tmp_path / "b")


def test_the_model_task_end_phases_end_the_live_task(tmp_path: Path) -> None:
    """A model whose task ends with 'finished' ends a live task on 'finished' too."""
    from rcbht_introspection.live.belief import BeliefTracker

    task = Task(PICK, ("finished",))
    trials = load_trials([_bag(tmp_path, s) for s in range(3)], "engine")
    model = train_model([s for t in trials for s in t.samples], task=task)
    tracker = BeliefTracker(model)
    assert tracker.phase("reach", 0.0) and tracker.phase("finished", 1.0)
    assert tracker.task_ended and tracker.end_phases == ("done", "finished")


def _bag(tmp_path: Path, seed: int) -> Path:
    """A pick trial written as a bag."""
    path = tmp_path / f"pick-{seed}.mcap"
    write_trial_bag(_pick_trial(seed), path)
    return path


def test_state_time_past_the_data_is_a_named_error(tmp_path: Path) -> None:
    trial = _pick_trial(2)
    late = replace(trial, state_times=(*trial.state_times[:-1], trial.end_time + 1.0))
    with pytest.raises(InputError, match=r"sub-task 'release' starts at .* after the last sample"):
        check_phases(late, "x")
    write_trial(trial, tmp_path / "trial")
    (tmp_path / "trial" / "R_State.dat").write_text("0\n0.9\n0.5\n")
    with pytest.raises(InputError, match=r"R_State\.dat, line 3, field state time: state time out"):
        read_trial(tmp_path / "trial", strict=True)
    assert read_trial(tmp_path / "trial").state_times == (0.0, 0.9)  # by default: dropped


def test_trial_folder_with_a_task_file_and_model_carry_the_names(tmp_path: Path) -> None:
    """A trial folder's task.yaml names its state times; the model file stores the task."""
    task = Task(PICK, ("done",), "pick")
    for seed in range(6):
        trial = _pick_trial(seed)
        write_trial(trial, tmp_path / "set" / trial.name, task=task)
    assert read_trial(tmp_path / "set" / "pick-00").phases == PICK
    trials = load_trials([tmp_path / "set"], "engine")
    assert task_of_trials(trials) == task and all(t.complete for t in trials)
    model = train_model([s for t in trials for s in t.samples], "mondrian", n_estimators=5)
    assert model.task.subtasks == PICK and set(model.classes_) == set(PICK)
    path = save_model(model, tmp_path / "pick.rcbht")
    loaded, why = load_subtask_model(str(path))
    assert why == "" and loaded is not None and loaded.task == Task(PICK)


def test_model_file_without_a_task_is_a_hiro_model(tmp_path: Path, sim_data: Path) -> None:
    """Files written before models stored their task load as HIRO models."""
    trials = load_trials(find_trials([sim_data / SIM_SUCCESS])[:3], "engine")
    model = train_model([s for t in trials for s in t.samples])
    path = save_model(model, tmp_path / "m.rcbht")
    with np.load(path, allow_pickle=False) as arrays:
        files = {k: arrays[k] for k in arrays.files}
    header = json.loads(files["header"].tobytes().decode())
    assert header["task"]["subtasks"] == list(HIRO_TASK.subtasks)
    del header["task"]
    from rcbht_introspection.io.safe_file import checksum

    header["checksum"] = checksum(header, {k: v for k, v in files.items() if k != "header"})
    files["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    with (tmp_path / "old.rcbht").open("wb") as handle:
        np.savez_compressed(handle, **files)  # type: ignore[arg-type]
    assert load_model(tmp_path / "old.rcbht").task == HIRO_TASK

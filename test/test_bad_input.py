"""Bad input is counted and named, and the run goes on; `--strict` keeps the errors: state times
after the data or out of order, labels rows for trials not given, duplicate trial names, a
`--train` test set of any size, and progress that is plain lines off a terminal."""

from __future__ import annotations

import dataclasses
import io
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import SIM_SUCCESS

from rcbht_introspection.cli import main
from rcbht_introspection.errors import InputError
from rcbht_introspection.io.hiro import (
    DROPPED_STATE_TIMES,
    dropped_state_times,
    find_trials,
    read_state_times,
    read_trial,
    write_trial,
)
from rcbht_introspection.io.trial import Trial

LATE = 99.0
"""A published state time after every trial's last sample (as 174 OpenHRP trials have)."""
LABELS_HEADER = "trial,outcome,failure_class,onset_s,dev_x_mm,dev_y_mm,dev_yaw_deg\n"


def _trial(name: str = "T-01", seconds: float = 10.0) -> Trial:
    """A one-arm trial at 100 Hz with four sub-tasks starting at 0, 2, 5 and 7 s."""
    time = np.arange(0.0, seconds + 1e-9, 0.01)
    rng = np.random.default_rng(0)
    return Trial(name, time, {"R": rng.normal(size=(len(time), 6))}, (0.0, 2.0, 5.0, 7.0))


def test_state_times_after_the_data_or_out_of_order_are_dropped_and_recorded(
    tmp_path: Path,
) -> None:
    folder = write_trial(_trial(), tmp_path / "T-01")
    state = folder / "R_State.dat"
    state.write_text("0\n2\n1.5\n7\n30\n")  # line 3 out of order, line 5 after the data (10 s)
    trial = read_trial(folder)
    assert trial.state_times == (0.0, 2.0, 7.0)
    # a time dropped in the middle leaves its sub-task out; the next keeps its own name
    assert trial.phase_names == ("approach", "rotation", "mating")
    assert trial.metadata[DROPPED_STATE_TIMES] == [
        {"line": 3, "time": 1.5, "reason": "out of order"},
        {"line": 5, "time": 30.0, "reason": "after the data"},
    ]
    assert dropped_state_times(trial) == 2
    with pytest.raises(InputError, match=r"R_State\.dat, line 3, field state time: state time out"):
        read_trial(folder, strict=True)
    with pytest.raises(InputError, match="line 3, field state time: state time out of order"):
        read_state_times(state, strict=True)
    state.write_text("0\n2\n5\n7\n30\n")  # only the extra line after the data: HIRO names stay
    trial = read_trial(folder)
    assert trial.state_times == (0.0, 2.0, 5.0, 7.0) and trial.phases == ()
    assert dropped_state_times(trial) == 1
    state.write_text("0\n30\n")
    assert read_trial(folder).state_times == (0.0,)
    with pytest.raises(InputError, match=r"sub-task 'rotation' starts at 30\.0 s, after the last"):
        read_trial(folder, strict=True)
    state.write_text("0\n2\n5\n7\n")
    assert DROPPED_STATE_TIMES not in read_trial(folder).metadata


def test_a_task_folder_keeps_the_sub_task_of_each_line(tmp_path: Path) -> None:
    from rcbht_introspection.task import Task

    task = Task(("reach", "grasp", "lift", "place"), ("done",), "pick")
    trial = dataclasses.replace(_trial(), phases=task.subtasks)
    folder = write_trial(trial, tmp_path / "T-01", task=task)
    (folder / "R_State.dat").write_text("0\n5\n2\n7\n")
    got = read_trial(folder)
    assert got.state_times == (0.0, 5.0, 7.0) and got.phases == ("reach", "grasp", "place")


@pytest.fixture
def dataset(sim_data: Path, tmp_path: Path) -> Path:
    """The generated successes, copied; the first three with a state time after their data."""
    root = tmp_path / "data"
    for i, folder in enumerate(find_trials([sim_data / SIM_SUCCESS])):
        shutil.copytree(folder, root / folder.name)
        if i < 3:
            with (root / folder.name / "R_State.dat").open("a") as handle:
                handle.write(f"{LATE}\n")
    return root


def _late(dataset: Path) -> list[str]:
    return sorted(p.name for p in dataset.iterdir())[:3]


def test_train_evaluate_and_label_count_dropped_state_times(
    dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    late = _late(dataset)
    summary = "dropped 3 state times after the trial's last sample or out of order, in 3 of 8"
    model = tmp_path / "m.rcbht"
    train = ["train", str(dataset), "--out", str(model), "--no-live-augment"]
    assert main(train) == 0
    assert f"rcbht train: {summary} trials ({', '.join(late)}); --strict" in capsys.readouterr().err
    assert main([*train, "--strict"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{late[0]}/R_State.dat" in err and "after the last" in err
    out = tmp_path / "curve.json"
    evaluate = ["evaluate", str(dataset), "--permutations", "2", "--no-peers", "--json", str(out)]
    assert main(evaluate) == 0
    err = capsys.readouterr().err
    assert f"rcbht evaluate: {summary}" in err
    assert json.loads(out.read_text())["input"] == {
        "dropped_state_times": {"total": 3, "per_trial": dict.fromkeys(late, 1)}
    }
    # stderr is not a terminal here: plain progress lines, no carriage-return frames
    assert "\r" not in err
    progress = [line for line in err.splitlines() if line.startswith("forest/words-wrench: ")]
    assert (
        1 <= len(progress) <= 11
        and progress[-1].split()[1].split("/")[0] == (progress[-1].split()[1].split("/")[1])
    )
    assert main(["label", str(dataset), "--out", str(tmp_path / "words")]) == 0
    assert f"rcbht label: {summary}" in capsys.readouterr().err
    assert main(["label", str(dataset), "--out", str(tmp_path / "w2"), "--strict"]) == 2


def test_verify_commands_put_the_counts_into_their_json(
    dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """verify-train stores and prints them; verify-eval with --train takes a test set of two
    trials (no folds are made) and keys the training trials train:<name>."""
    late = _late(dataset)
    labels = tmp_path / "labels.csv"
    labels.write_text(
        LABELS_HEADER + "".join(f"{n},success,,,,,\n" for n in late) + "ghost-1,success,,,,,\n"
        "ghost-2,failure,slip,,,,\n"
    )
    args = ["verify-train", str(dataset), "--labels", str(labels), "--out", str(tmp_path / "v")]
    assert main(args) == 0
    captured = capsys.readouterr()
    assert "rcbht verify-train: dropped 3 state times" in captured.err
    assert (
        f"warning: {labels}: 2 of 5 rows name trials not given (ghost-1, ghost-2)" in captured.err
    )
    printed = json.loads(captured.out.split(": ", 1)[1])
    assert printed["input"] == {
        "dropped_state_times": {"total": 3, "per_trial": dict.fromkeys(late, 1)},
        "labels_rows_not_given": 2,
    }
    assert main([*args, "--strict"]) == 2
    err = capsys.readouterr().err
    assert f"{late[0]}/R_State.dat" in err and "after the last sample" in err
    test_set, train_set, clean = tmp_path / "test", tmp_path / "train", tmp_path / "clean"
    names = sorted(p.name for p in dataset.iterdir())
    for i, name in enumerate(names):
        shutil.copytree(dataset / name, (test_set if i in (0, 7) else train_set) / name)
        if i >= 3:
            shutil.copytree(dataset / name, clean / name)
    strict = ["verify-train", str(clean), "--labels", str(labels), "--strict", "--out", "v2"]
    assert main(strict) == 2
    assert f"{labels}, line 2, field trial: trial '{late[0]}' is not among the given trials" in (
        capsys.readouterr().err
    )
    out = tmp_path / "eval.json"
    evaluate = ["verify-eval", str(test_set), "--train", str(train_set), "--json", str(out)]
    assert main([*evaluate, "--labels", str(labels)]) == 0
    result = json.loads(out.read_text())
    assert result["protocol"]["folds"] == "transfer"
    assert [r["trial"] for r in result["records"] if r["method"] == "verifier"] == [
        names[0],
        names[7],
    ]
    assert result["input"] == {
        "dropped_state_times": {
            "total": 3,
            "per_trial": {names[0]: 1, f"train:{names[1]}": 1, f"train:{names[2]}": 1},
        },
        "labels_rows_not_given": 2,
    }


def test_labels_rows_for_trials_not_given_are_an_error_only_when_strict(tmp_path: Path) -> None:
    from rcbht_introspection.verify.labels import check_labels_cover, read_labels

    labels = tmp_path / "labels.csv"
    labels.write_text(LABELS_HEADER + "T-01,success,,,,,\nT-09,failure,slip,1.0,,,\n")
    rows = read_labels(labels)
    trials = [_trial("T-01")]
    assert check_labels_cover(labels, rows, trials) == ["T-09"]
    with pytest.raises(InputError, match=r"line 3, field trial: trial 'T-09' is not among"):
        check_labels_cover(labels, rows, trials, strict=True)
    labels.write_text(LABELS_HEADER + "T-01,failure,slip,11.0,,,\n")  # onset after the end: always
    with pytest.raises(InputError, match=r"onset 11\.0 s is after the trial's end"):
        check_labels_cover(labels, read_labels(labels), trials)


def test_duplicate_trial_names_name_both_sources(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    first = write_trial(_trial("T-01"), tmp_path / "a" / "T-01")
    second = write_trial(_trial("T-01"), tmp_path / "b" / "T-01")
    write_trial(_trial("T-02"), tmp_path / "a" / "T-02")
    args = ["verify-train", str(tmp_path / "a"), str(tmp_path / "b"), "--out", "v.npz"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"two trials are named 'T-01': {first} and {second}" in err


def test_duplicate_input_bag_names_name_both_paths(tmp_path: Path) -> None:
    from rcbht_introspection.io.bag_import import ImportOptions, plan_imports

    paths = [tmp_path / "day1" / "run.bag", tmp_path / "day2" / "run.bag"]
    with pytest.raises(InputError, match=f"two input bags are named 'run', {paths[0]} and"):
        plan_imports(paths, tmp_path / "out", ImportOptions(phase="/state"))[0].run()


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_is_a_bar_on_a_terminal_and_plain_lines_otherwise() -> None:
    from rcbht_introspection.commands.progress import progress_bar

    plain, terminal = io.StringIO(), _Terminal()
    for stream in (plain, terminal):
        bar = progress_bar(240, "svm/compact", "step", stream)
        for _ in range(240):
            bar.update(1)
        bar.close()
    lines = plain.getvalue().splitlines()
    assert "\r" not in plain.getvalue() and len(lines) == 10
    assert lines[0].startswith("svm/compact: 24/240 steps (10%), ")
    assert lines[-1].startswith("svm/compact: 240/240 steps (100%), ")
    assert "\r" in terminal.getvalue()  # tqdm redraws its bar in place
    odd = io.StringIO()
    bar = progress_bar(7, "prequential", "teach", odd)
    bar.update(3)
    bar.update(2)
    bar.close()
    assert [line.split(",")[0] for line in odd.getvalue().splitlines()] == [
        "prequential: 3/7 teaches (43%)",
        "prequential: 5/7 teaches (71%)",
    ]

"""Another task end to end, as docs/your-robot.md walks it: bags of the simulated peg-in-hole (its
own four phase names, a noisy 100 Hz sensor) through `rcbht calibrate`, `rcbht train`, `rcbht
evaluate` and `rcbht replay-eval`, whose segmenter_node process takes the calibrated profile from
the model file and whose classifier_node publishes the task's names on /task_state."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from ros_support import require_ros

from rcbht_introspection.cli import main
from rcbht_introspection.io.bags import read_trial_bag

pytestmark = [pytest.mark.ros]

PEG = ("reach", "search", "insert", "release")
"""The peg-in-hole task's sub-tasks (config/sim/peg.yaml), none of them HIRO's."""
TRIALS = 8
HELD_OUT = 2
RATE = "5"
"""Replay speed: 500 Hz of the 100 Hz sensor; the verdicts wait for every word, and the harness
compares them with the offline run, so a fast replay checks what a real-time one does."""


@pytest.fixture(scope="module")
def peg_bags(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    out = tmp_path_factory.mktemp("peg")
    args = ["sim", "--task", "peg-in-hole", "--trials", str(TRIALS), "--seed", "5"]
    assert main([*args, "--format", "bag", "--out", str(out), "--progress", "off"]) == 0
    bags = sorted(out.glob("*.mcap"))
    assert len(bags) == TRIALS
    return bags


def test_a_second_task_trains_evaluates_and_runs_live(
    peg_bags: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    require_ros()
    assert read_trial_bag(peg_bags[0]).phases == PEG
    train, held_out = peg_bags[:-HELD_OUT], peg_bags[-HELD_OUT:]
    profile = tmp_path / "peg_sensor.yaml"
    assert main(["calibrate", *map(str, train), "--out", str(profile)]) == 0
    calibrated = ["--taxonomy-config", str(profile)]
    model = tmp_path / "peg.rcbht"
    assert main(["train", *map(str, train), *calibrated, "--out", str(model)]) == 0
    from rcbht_introspection.learn.model_file import load_model

    trained = load_model(model)
    assert trained.task.subtasks == PEG and sorted(trained.classes_) == sorted(PEG)
    assert trained.taxonomy_profile == "peg_sensor"

    report = tmp_path / "evaluate.json"
    args = ["evaluate", *map(str, peg_bags), *calibrated, "--permutations", "1"]
    args += ["--validation-trials", "2", "--no-peers"]
    assert main([*args, "--no-variant", "--no-progress", "--json", str(report)]) == 0
    evaluated = json.loads(report.read_text())
    assert evaluated["confusion_labels"] == list(PEG) and evaluated["n_trials"] == TRIALS
    assert set(evaluated["per_class_accuracy"]) == set(PEG)

    scores = tmp_path / "replay.json"
    bags = [str(b) for b in held_out]
    # the calibrated model on reference-profile words is refused before any node starts
    assert main(["replay-eval", *bags, "--model", str(model), "--profile", "reference"]) == 2
    assert "trained on words of taxonomy profile 'peg_sensor'" in capsys.readouterr().err
    # no profile option: the segmenter labels with the profile the model file carries
    args = ["replay-eval", *bags, "--model", str(model), "--rate", RATE]
    assert main([*args, "--json", str(scores)]) == 0
    result = json.loads(scores.read_text())
    assert result["profile"] == "peg_sensor"
    assert result["clean_shutdown"], (result["exit_codes"], result.get("shutdown_logs"))
    assert result["dropped_wrench"] == 0
    assert result["subtasks"] == len(PEG) * HELD_OUT
    # the segmenter process labelled with the calibrated profile: its words equal the offline
    # engine's under that profile, and the model (trained on it) gives the same verdicts
    assert result["words_match_offline"], [b["words_mismatch"] for b in result["per_bag"]]
    assert result["verdicts_match_offline"], [
        (b["verdicts"], b["offline_verdicts"]) for b in result["per_bag"]
    ]
    for bag in result["per_bag"]:
        assert bag["truth"] == list(PEG)
        assert set(bag["verdicts"]) <= set(PEG)
        published = {state for _, state in bag["timeline"]} | {bag["initial_state"]}
        assert published <= {*PEG, "unknown"}, published  # /task_state, as received over DDS
        assert published & set(PEG), published

"""`rcbht demo`: the live main job on simulated trials, and a clear list of what is missing."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from ros_support import require_ros

from rcbht_introspection.cli import main


def test_demo_names_what_is_missing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("RCBHT_HIRO_DATA", str(tmp_path / "nowhere"))
    assert main(["demo", "--out", str(tmp_path / "out"), "--data", "hiro"]) == 1
    out = capsys.readouterr().out
    assert "rcbht demo cannot run; missing:" in out
    assert "REAL HIRO trials (../shared/data/hiro or $RCBHT_HIRO_DATA)" in out


@pytest.mark.ros
@pytest.mark.slow
def test_demo_on_simulated_trials(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    require_ros()
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--trials", "3", "--held-out", "1"]) == 0
    text = capsys.readouterr().out
    assert "/task_state: start" in text and "subtask_accuracy" in text
    result = json.loads((out / "replay_eval.json").read_text())
    assert result["source"] == "simulator" and result["subtasks"] == 4
    assert result["words_match_offline"] and result["verdicts_match_offline"]
    assert result["dropped_wrench"] == 0 and result["clean_shutdown"]
    assert (out / "task_state_timeline.png").stat().st_size > 10_000
    verified = json.loads((out / "verify_eval.json").read_text())
    runs = {r["failure_class"] or r["outcome"]: r for r in verified["runs"]}
    assert set(runs) == {"success", "deviation_x+"}  # one nominal, one failing held-out trial
    assert all(r["matches_offline"] for r in runs.values())  # the node alarms as offline
    assert "verifier: detection_accuracy" in text
    assert len(list(out.glob("failure_timeline_*.png"))) == 2
    loop = json.loads((out / "closed_loop.json").read_text())  # the closed loop over ROS
    kinds = [d["kind"] for d in loop["decisions"]]
    assert kinds[:2] == ["attempt", "abort"] and kinds[-1] == "stop", loop["decisions"]
    assert loop["decisions"][-1]["reason"] == "seated" and len(kinds) == 4, loop["decisions"]
    assert set(loop["exit_codes"].values()) == {0}, loop["exit_codes"]
    assert (out / "closed_loop_timeline.png").stat().st_size > 10_000


def test_demo_task_choice_is_for_simulated_data(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["demo", "--out", str(tmp_path / "out"), "--data", "hiro", "--task", "peg-in-hole"]
    assert main(args) == 2
    assert "--task chooses a simulated task" in capsys.readouterr().err

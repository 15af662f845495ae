"""Another robot end to end: the real Baxter ROS 1 bags imported with one command line (no CSV),
the taxonomy calibrated to its sensor, sub-tasks learnt under their tag names, the verifier fitted
on one day, and two bags of other days replayed through the node processes over real DDS: the
nodes must say what offline says, name the sub-tasks, and raise no alarm on these successes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import HIRO, require
from ros_support import require_ros

from rcbht_introspection.cli import main

pytestmark = [pytest.mark.ros, pytest.mark.shared_data, pytest.mark.slow]

BAXTER = HIRO.parent / "baxter_pick_and_place"
SUBTASKS = ["approach", "grasp", "lift", "transport", "place"]
PHASE_MAP = "0=-,1=approach,2=grasp,5=lift,3=transport,4=place"
OTHER_DAYS = ("c0909_s07", "d0914_s01")


def _import(out: Path) -> tuple[list[str], list[str]]:
    """session_a's 15 bags and two of other days as trial bags; their paths."""
    bags = sorted(BAXTER.glob("session_a/*.bag"))
    bags += [BAXTER / "other_sessions" / f"{name}.bag" for name in OTHER_DAYS]
    topics = ["--wrench", "/tag_multimodal.wrench_stamped", "--phase", "/tag_multimodal.tag"]
    args = ["bag", "import", *map(str, bags), "--out", str(out), *topics, "--phase-map", PHASE_MAP]
    assert main(args) == 0
    day = sorted(map(str, out.glob("s??.mcap")))
    return day, [str(out / f"{name}.mcap") for name in OTHER_DAYS]


def test_baxter_bags_import_calibrate_train_verify_and_replay_over_dds(tmp_path: Path) -> None:
    require_ros()
    require(BAXTER.is_dir(), f"Baxter bags not found at {BAXTER}")
    day, others = _import(tmp_path / "bags")
    assert len(day) == 15
    profile, model, verifier = (tmp_path / n for n in ("baxter.yaml", "m.skops", "v.skops"))
    assert main(["calibrate", *day, "--out", str(profile)]) == 0
    taxonomy = ["--taxonomy-config", str(profile)]
    curve_file = tmp_path / "curve.json"
    assert main(["evaluate", *day, *taxonomy, "--permutations", "3", "--no-progress", "--no-peers",
                 "--json", str(curve_file)]) == 0  # fmt: skip
    curve = json.loads(curve_file.read_text())
    assert curve["task"]["subtasks"] == SUBTASKS
    assert curve["steady_state_accuracy"]["mean"] >= 0.95
    assert main(["train", *day, *taxonomy, "--out", str(model)]) == 0
    assert main(["verify-train", *day, "--out", str(verifier)]) == 0
    out = tmp_path / "replay.json"
    assert main(["replay-eval", *others, "--model", str(model), "--verifier", str(verifier),
                 *taxonomy, "--rate", "5", "--json", str(out)]) == 0  # fmt: skip
    result = json.loads(out.read_text())
    assert result["clean_shutdown"], (result["exit_codes"], result.get("shutdown_logs"))
    assert result["dropped_wrench"] == 0
    assert result["words_match_offline"], [b["words_mismatch"] for b in result["per_bag"]]
    assert result["verdicts_match_offline"]
    assert result["subtasks"] == len(SUBTASKS) * len(others)
    assert result["subtask_accuracy"] >= 0.8, [b["verdicts"] for b in result["per_bag"]]
    summary = result["verifier"]["summary"]
    assert summary["nominal_runs"] == len(others)
    assert summary["false_alarms_per_nominal_run"] == 0.0

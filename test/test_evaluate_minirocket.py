"""`rcbht evaluate`'s minirocket_baseline: MiniRocket on each sub-task's raw wrench, scored on the
model's own permutations, splits and steps; deterministic; absent (with a note, never an error)
when aeon cannot be imported or with --no-peers."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import SIM_SUCCESS, dataset_root

from rcbht_introspection.cli import main
from rcbht_introspection.grammar.split import SubtaskSample
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.peers.subtask_baseline import SubtaskWrench
from rcbht_introspection.taxonomy.words import TrialWords

REPO = Path(__file__).resolve().parents[1]
PERMUTATIONS = ["--permutations", "2", "--no-progress"]
MODEL_KEYS = ("steady_state_accuracy", "curve", "trial_splits", "best_of_splits",
              "confusion_matrix", "duration_baseline", "without_near_empty")  # fmt: skip


def _evaluate(data: Path, out: Path, *extra: str) -> dict[str, Any]:
    assert main(["evaluate", str(data), *PERMUTATIONS, "--json", str(out), *extra]) == 0
    result: dict[str, Any] = json.loads(out.read_text())
    return result


def test_minirocket_baseline_is_scored_on_the_model_s_splits(
    request: pytest.FixtureRequest, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = dataset_root(request, SIM_SUCCESS)
    result = _evaluate(data, tmp_path / "a.json")
    peer = result["minirocket_baseline"]
    chance = 1 / len(result["confusion_labels"])
    assert chance < peer["mean"] <= 1 and 0 <= peer["std"] <= 1
    assert [c["n_train_trials"] for c in peer["curve"]] == result["steady_state_steps"]
    assert peer["mean"] == pytest.approx(np.mean([c["mean"] for c in peer["curve"]]))
    splits = peer["trial_splits"]
    assert chance < splits["mean"] <= 1 and splits["n"] == result["trial_splits"]["n"] == 2
    # the same validation sub-tasks as the model's trial splits (its confusion matrix counts them)
    assert peer["n_subtasks"] == sum(map(sum, result["confusion_matrix"])) > 0
    assert set(result["prefix_accuracy"]) == {"10%", "25%", "50%", "75%"}
    for figures in result["prefix_accuracy"].values():
        assert 0 <= figures["minirocket_baseline"] <= 1
    assert result["prefix_accuracy"]["75%"]["minirocket_baseline"] > chance
    out = capsys.readouterr().out
    assert f"minirocket {peer['mean']:.4f} +- {peer['std']:.4f}" in out

    # deterministic for a seed; the package model's figures do not depend on the peer's run
    assert _evaluate(data, tmp_path / "b.json")["minirocket_baseline"] == peer
    without = _evaluate(data, tmp_path / "c.json", "--no-peers")
    assert "minirocket_baseline" not in without
    assert "aeon" not in capsys.readouterr().err
    for key in MODEL_KEYS:
        assert without[key] == result[key], key
    for key, figures in result["prefix_accuracy"].items():
        assert {k: v for k, v in figures.items() if k != "minirocket_baseline"} == without[
            "prefix_accuracy"
        ][key]


def test_without_aeon_evaluate_succeeds_without_the_column(
    request: pytest.FixtureRequest, tmp_path: Path
) -> None:
    data, out = dataset_root(request, SIM_SUCCESS), tmp_path / "out.json"
    argv = ["evaluate", str(data), *PERMUTATIONS, "--no-variant", "--json", str(out)]
    code = (
        "import sys\nsys.modules['aeon'] = None\n"
        "from rcbht_introspection.cli import main\n"
        f"sys.exit(main({argv!r}))\n"
    )
    run = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=300
    )
    assert run.returncode == 0, run.stderr
    notes = [line for line in run.stderr.splitlines() if "aeon" in line]
    assert len(notes) == 1 and "minirocket_baseline" in notes[0], run.stderr
    result = json.loads(out.read_text())
    assert "minirocket_baseline" not in result and "duration_baseline" in result
    assert all("minirocket_baseline" not in f for f in result["prefix_accuracy"].values())
    assert "minirocket" not in run.stdout


def test_a_sub_task_window_holds_every_arm_s_wrench_between_its_times() -> None:
    time = np.arange(100) / 100
    frames = {arm: np.column_stack([time + 10 * k + i for k in range(6)]) for i, arm in
              enumerate(("R", "L"))}  # fmt: skip
    trial = Trial("t", time, frames, state_times=(0.0, 0.5))
    wrench = SubtaskWrench({"t": trial})

    def sample(start: float, end: float) -> SubtaskSample:
        return SubtaskSample("t", "x", start, end, TrialWords(name="t"))

    (whole,) = wrench.windows([sample(0.2, 0.4)])
    assert whole.shape == (21, 12)  # 0.20 .. 0.40, both arms' six axes side by side
    # relative to the window's first sample: L's offset (arms in name order, L first) cancels
    np.testing.assert_allclose(whole[:, 0], time[20:41] - time[20])
    np.testing.assert_allclose(whole[:, 6], time[20:41] - time[20])
    np.testing.assert_allclose(whole[:, 11], time[20:41] - time[20])
    (half,) = wrench.windows([sample(0.2, 0.4)], fraction=0.5)
    np.testing.assert_allclose(half[:, 6], time[20:31] - time[20])
    (short,) = wrench.windows([sample(0.502, 0.507)])  # between two samples: the nearest one
    assert short.shape == (1, 12) and not short.any()

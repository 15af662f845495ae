"""`rcbht evaluate` and `rcbht train` in-process on a few REAL or generated trials (tiny protocol)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import REAL, SIM_FAILURE, SIM_JAMMED, SOURCES, dataset_root, generated_trials

from rcbht_introspection.cli import main
from rcbht_introspection.learn.data import load_trials
from rcbht_introspection.learn.evaluate import Protocol, evaluate
from rcbht_introspection.learn.model_file import load_model

KEYS = {"steady_state_accuracy", "curve", "per_class_accuracy", "confusion_matrix", "best_of_splits",
        "fit_seconds", "predict_ms", "duration_baseline", "prefix_accuracy", "without_near_empty"}  # fmt: skip


def _subset(folders: list[Path], out: Path) -> Path:
    """A data set folder of symlinks to `folders`."""
    out.mkdir()
    for trial in folders:
        (out / trial.name).symlink_to(trial)
    return out


@pytest.mark.parametrize(
    ("source", "curve", "near_empty"),
    [  # REAL trials 19..28 mix long and 5 ms rotations; the generated trials have no short one
        pytest.param("hiro", [3, 4, 5, 6, 7], True, marks=pytest.mark.shared_data, id="hiro"),
        pytest.param("sim", [3, 4, 5], False, id="sim"),
    ],
)
def test_evaluate_writes_the_documented_json_and_plot(
    request: pytest.FixtureRequest, tmp_path: Path, source: str, curve: list[int], near_empty: bool
) -> None:
    if source == "hiro":
        trials = sorted(dataset_root(request, REAL).iterdir())[18:28]
    else:
        trials = generated_trials(request)
    data = _subset(trials, tmp_path / "subset")
    out, png = tmp_path / "eval.json", tmp_path / "curve.png"
    code = main(["evaluate", str(data), "--classifier", "mondrian", "--n-estimators", "10",
                 "--permutations", "2", "--validation-trials", "3", "--no-peers", "--json", str(out),
                 "--plot", str(png), "--no-progress"])  # fmt: skip
    assert code == 0 and png.stat().st_size > 1000
    result = json.loads(out.read_text())
    assert set(result) >= KEYS
    assert [p["n_train_trials"] for p in result["curve"]] == curve
    assert 0.0 <= result["steady_state_accuracy"]["mean"] <= 1.0
    assert set(result["steady_state_accuracy"]) == {"mean", "std"}
    assert sum(map(sum, result["confusion_matrix"])) == 2 * 3 * 4
    assert result["confusion_labels"] == ["approach", "rotation", "insertion", "mating"]
    assert set(result["prefix_accuracy"]) == {"10%", "25%", "50%", "75%"}
    assert (result["without_near_empty"]["n_samples_removed"] > 0) is near_empty
    assert result["best_of_splits"] >= result["trial_splits"]["mean"]
    assert result["duration_baseline"]["curve"][0]["n_train_trials"] == 3


@pytest.mark.parametrize("source", SOURCES)
def test_svm_curve_starts_at_one_trial_and_excludes_incomplete_trials(
    request: pytest.FixtureRequest, source: str
) -> None:
    """Five complete trials and one without all four sub-tasks (REAL: SideApproach, a SIM trial
    of the shared set; generated: a jammed trial aborted after three sub-tasks)."""
    if source == "hiro":
        sim = sorted(dataset_root(request, "SIM_HIRO_ONE_SA_SUCCESS").iterdir())
        names = [p for p in sim if p.name.startswith("20160911-21")][:6]
        incomplete = "20160911-2136-SideApproach-S"
    else:
        incomplete = SIM_JAMMED
        names = [*generated_trials(request)[:5], dataset_root(request, SIM_FAILURE) / incomplete]
    trials = load_trials(names)
    assert any(not t.complete for t in trials)
    result = evaluate(
        trials, Protocol(classifier="svm", permutations=1, n_validation=2, variant=False)
    )
    assert result["excluded_trials"] == [incomplete]
    assert result["curve"][0]["n_train_trials"] == 1
    assert result["n_trials"] == len(trials) - 1


@pytest.mark.parametrize("source", SOURCES)
def test_train_writes_a_loadable_model(
    request: pytest.FixtureRequest, tmp_path: Path, capsys: pytest.CaptureFixture[str], source: str
) -> None:
    if source == "hiro":
        trials = sorted(dataset_root(request, REAL).iterdir())[20:24]
    else:
        trials = generated_trials(request)[:4]
    out = tmp_path / "model.npz"
    budget = ["--max-nodes", "300", "--max-points", "10"]
    assert main(["train", *map(str, trials), "--out", str(out), "--classifier", "mondrian",
                 *budget]) == 0  # fmt: skip
    assert "16 samples" in capsys.readouterr().out
    model = load_model(out, expect_encoding="words-wrench")
    assert model.classifier == "mondrian" and len(model.classes_) == 4
    for head in (model, model.live or model):
        forest = head.estimator
        assert (forest.max_nodes, forest.max_points) == (300, 10)
        assert forest.n_nodes_ <= 300 and forest.n_stored_points_ <= 10


def test_bad_inputs_are_one_line_errors(tmp_path: Path, capsys) -> None:
    assert main(["evaluate", str(tmp_path / "none"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("rcbht evaluate: error:") and err.count("\n") == 1
    for option in (["--max-nodes", "500"], ["--classifier", "mondrian", "--max-nodes", "50"]):
        assert main(["evaluate", str(tmp_path), "--no-progress", *option]) == 2
        err = capsys.readouterr().err
        assert "--max-nodes" in err and err.count("\n") == 1

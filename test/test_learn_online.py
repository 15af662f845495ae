"""OnlineLearner (learn/online.py) and `rcbht evaluate --protocol prequential` on generated and
REAL trials: warm-up is batch training, then a frozen encoding and a growing forest, snapshots
that later teaching never changes, model files that teaching continues from."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import REAL, SOURCES, dataset_root, generated_trials, golden_or_engine, trial_folders

from rcbht_introspection.cli import main
from rcbht_introspection.errors import InputError
from rcbht_introspection.learn.data import TrialSamples, load_trials
from rcbht_introspection.learn.model_file import load_model, load_subtask_model, save_model
from rcbht_introspection.learn.models import SubtaskModel, train_model
from rcbht_introspection.learn.online import OnlineLearner, TeachConfig, load_teach_config

SMALL = TeachConfig(warmup_windows=8, prefixes=(0.5,), n_estimators=8, encoding="compact")
"""Two four-sub-task trials of warm-up, few trees: quick and still exercising both phases."""


def _trials(request: pytest.FixtureRequest, source: str) -> list[TrialSamples]:
    """Five complete trials: REAL S-20..S-24 (golden words) or the first five generated ones."""
    hiro = [f"20121127-HIROSA-S-{i:02d}" for i in range(20, 25)]
    folders = trial_folders(request, source, hiro, range(5))
    return load_trials(folders, golden_or_engine(source))


def _forest_points(model: SubtaskModel) -> int:
    """Training points the model's forest holds."""
    return len(model.estimator.learned_state().y)


def _held(trials: list[TrialSamples]) -> list:
    return [s for t in trials[-1:] for s in t.samples]


@pytest.mark.parametrize("source", SOURCES)
def test_warmup_refit_equals_train_model_on_the_same_windows(
    request: pytest.FixtureRequest, source: str
) -> None:
    trials = _trials(request, source)
    config = replace(SMALL, warmup_windows=100)
    learner = OnlineLearner(config, random_state=3)
    for trial in trials[:3]:
        snapshot = learner.teach(trial.samples)
    windows = [s for t in trials[:3] for s in t.samples]
    batch = train_model(
        windows, "mondrian", "compact", random_state=3, n_estimators=config.n_estimators,
        augment_prefixes=config.prefixes,
    )  # fmt: skip
    held = _held(trials)
    assert learner.refits == 3 and learner.warming_up and learner.taught_windows == len(windows)
    assert snapshot.encoder.feature_names == batch.encoder.feature_names
    assert snapshot.predict_samples(held) == batch.predict_samples(held)
    np.testing.assert_array_equal(
        snapshot.predict_proba_samples(held), batch.predict_proba_samples(held)
    )


@pytest.mark.parametrize("source", SOURCES)
def test_after_warmup_the_encoding_is_frozen_and_partial_fit_extends_the_forest(
    request: pytest.FixtureRequest, source: str
) -> None:
    trials = _trials(request, source)
    learner = OnlineLearner(SMALL)
    learner.teach(trials[0].samples)
    warm = learner.teach(trials[1].samples)
    assert not learner.warming_up and learner.refits == 2
    assert warm.training["online"]["frozen"] is True
    later = learner.teach(trials[2].samples)
    assert learner.refits == 2, "a teach after warm-up must not refit"
    assert later.encoder.to_state() == warm.encoder.to_state()
    added = len(trials[2].samples) * (1 + len(SMALL.prefixes))
    assert _forest_points(later) == _forest_points(warm) + added
    assert later.training["online"]["taught_windows"] == 12
    assert later.estimator is not warm.estimator


def test_a_snapshot_is_not_changed_by_later_teaching(request: pytest.FixtureRequest) -> None:
    trials = _trials(request, "sim")
    learner = OnlineLearner(SMALL)
    for trial in trials[:2]:
        snapshot = learner.teach(trial.samples)
    held = _held(trials)
    before = snapshot.predict_proba_samples(held)
    points = _forest_points(snapshot)
    for trial in trials[2:4]:
        latest = learner.teach(trial.samples)
    assert learner.model is latest and latest is not snapshot
    assert _forest_points(snapshot) == points < _forest_points(latest)
    np.testing.assert_array_equal(snapshot.predict_proba_samples(held), before)
    assert snapshot.training["online"]["taught_windows"] == 8


def test_a_saved_model_continues_teaching_like_the_one_in_memory(
    request: pytest.FixtureRequest, tmp_path: Path
) -> None:
    trials = _trials(request, "sim")
    learner = OnlineLearner(SMALL)
    for trial in trials[:3]:
        snapshot = learner.teach(trial.samples)
    path = save_model(snapshot, tmp_path / "taught.npz")
    resumed = OnlineLearner(SMALL, model=load_model(path))
    assert resumed.taught_windows == learner.taught_windows == 12
    assert resumed.model is not None and not resumed.warming_up
    from_file = resumed.teach(trials[3].samples)
    in_memory = learner.teach(trials[3].samples)
    assert resumed.refits == 0
    assert _forest_points(from_file) == _forest_points(in_memory)
    held = _held(trials)
    np.testing.assert_array_equal(
        from_file.predict_proba_samples(held), in_memory.predict_proba_samples(held)
    )


def test_a_model_given_during_warmup_still_continues_with_partial_fit(
    request: pytest.FixtureRequest,
) -> None:
    """A model file has no kept windows to refit from, whatever warmup_windows says."""
    trials = _trials(request, "sim")
    model = train_model(trials[0].samples, "mondrian", n_estimators=4)
    learner = OnlineLearner(replace(SMALL, warmup_windows=1000), model=model)
    taught = learner.teach(trials[1].samples)
    assert learner.refits == 0
    assert taught.encoder.to_state() == model.encoder.to_state()
    assert _forest_points(taught) == _forest_points(model) + 8


def test_teaching_a_model_that_is_not_mondrian_is_an_input_error(
    request: pytest.FixtureRequest,
) -> None:
    trials = _trials(request, "sim")
    svm = train_model([s for t in trials[:2] for s in t.samples], "svm")
    with pytest.raises(InputError, match="mondrian"):
        OnlineLearner(SMALL, model=svm)


def test_a_new_label_during_warmup_joins_the_classes(request: pytest.FixtureRequest) -> None:
    trials = _trials(request, "sim")
    learner = OnlineLearner(SMALL)
    learner.teach(trials[0].samples[:2])
    jammed = [replace(s, subtask="jamming") for s in trials[1].samples[2:]]
    model = learner.teach(jammed)
    assert "jamming" in model.classes_


def test_a_new_label_after_warmup_joins_the_classes(
    request: pytest.FixtureRequest, tmp_path: Path
) -> None:
    trials = _trials(request, "sim")
    learner = OnlineLearner(SMALL)
    for trial in trials[:2]:
        learner.teach(trial.samples)
    before = learner.model
    assert before is not None and not learner.warming_up
    jammed = [replace(s, subtask="jamming") for s in trials[2].samples]
    model = learner.teach(jammed)
    assert "jamming" in model.classes_
    assert "jamming" in model.predict_samples(jammed)
    # the task names it too (a saved model whose classes its task lacks is refused on load),
    # and the snapshot handed out before did not change
    assert model.task.subtasks[-1] == "jamming" and "jamming" not in before.task.subtasks
    path = save_model(model, tmp_path / "taught.rcbht")
    loaded, problem = load_subtask_model(str(path))
    assert loaded is not None, problem
    assert loaded.classes_ == model.classes_


def test_bad_teaching_input_is_a_one_line_input_error(
    request: pytest.FixtureRequest, tmp_path: Path
) -> None:
    trials = _trials(request, "sim")
    learner = OnlineLearner(SMALL)
    with pytest.raises(InputError, match="no windows"):
        learner.teach([])
    with pytest.raises(InputError, match="no label"):
        learner.teach([replace(trials[0].samples[0], subtask="")])
    assert learner.model is None and learner.taught_windows == 0
    bad = tmp_path / "teach.yaml"
    bad.write_text("teach:\n  warmup_windows: 4\n  prefixes: [0.5, 1.5]\n")
    with pytest.raises(InputError) as info:
        load_teach_config(bad)
    assert "teach.yaml" in str(info.value) and "prefixes" in str(info.value)
    assert "\n" not in str(info.value)
    assert load_teach_config() == TeachConfig()


@pytest.mark.parametrize("source", SOURCES)
def test_prequential_cli_writes_the_documented_json(
    request: pytest.FixtureRequest, tmp_path: Path, source: str
) -> None:
    if source == "hiro":
        folders = sorted(dataset_root(request, REAL).iterdir())[18:26]
    else:
        folders = generated_trials(request)
    data = tmp_path / "subset"
    data.mkdir()
    for trial in folders:
        (data / trial.name).symlink_to(trial)
    out = tmp_path / "prequential.json"
    code = main(["evaluate", str(data), "--protocol", "prequential", "--n-estimators", "5",
                 "--permutations", "1", "--held-out", "2", "--json", str(out),
                 "--no-progress"])  # fmt: skip
    assert code == 0
    result = json.loads(out.read_text())
    steps = [1, 2, 5]  # 6 taught trials of 8
    assert result["steps"] == steps and result["orders"] == 2
    assert result["held_out_trials"] == [p.name for p in folders[-2:]]
    for key in ("prequential", "batch", "svm", "duration"):
        assert len(result[f"{key}_accuracy"]) == len(result[f"{key}_std"]) == len(steps)
        assert all(0.0 <= a <= 1.0 for a in result[f"{key}_accuracy"])
    # the default warm-up (config/teach.yaml) covers these 6 trials: online = batch, exactly
    assert result["prequential_accuracy"] == result["batch_accuracy"]
    running = result["test_then_train_accuracy"]["curve"]
    assert running[0] is None and all(0.0 <= a <= 1.0 for a in running[1:])


def test_prequential_cli_refuses_options_of_the_curve_protocol(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for extra in (["--classifier", "svm"], ["--validation-trials", "3"], ["--plot", "x.png"]):
        args = ["evaluate", str(tmp_path), "--protocol", "prequential", "--no-progress", *extra]
        assert main(args) == 2
        err = capsys.readouterr().err
        assert err.startswith("rcbht evaluate: error:") and err.count("\n") == 1
    assert main(["evaluate", str(tmp_path), "--held-out", "3", "--no-progress"]) == 2
    assert "--protocol prequential" in capsys.readouterr().err

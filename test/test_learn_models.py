"""Sub-task models on golden words of REAL trials and on the engine's words of generated trials:
training, the safe model file (round trip, tampering, wrong version, wrong encoding, the taxonomy
profile it carries), online updates, and the near-empty rotation sub-task (REAL only)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import SIM_FAILURE, SIM_JAMMED, SIM_SUCCESS, SOURCES, dataset_root

from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar.split import SubtaskSample, prefix_sample
from rcbht_introspection.io.hiro import find_trials
from rcbht_introspection.io.safe_file import checksum
from rcbht_introspection.learn.data import load_samples, load_trials
from rcbht_introspection.learn.model_file import (
    load_model,
    model_file_taxonomy,
    model_taxonomy,
    save_model,
)
from rcbht_introspection.learn.models import (
    RUNNING_PREFIXES,
    VERDICT_TREES,
    train_model,
    with_prefixes,
)
from rcbht_introspection.taxonomy.config import default_config, taxonomy_digest

REAL = "REAL_HIRO_ONE_SA_SUCCESS"
# S-01..S-21 have a long rotation, S-22..S-46 a 5 ms one: take both kinds
TRAIN = ["20121127-HIROSA-S-01", "20121127-HIROSA-S-05", "20121127-HIROSA-S-09",
         "20121127-HIROSA-S-13", "20121127-HIROSA-S-24", "20121127-HIROSA-S-28",
         "20121127-HIROSA-S-32", "20121127-HIROSA-S-36"]  # fmt: skip
VALID = [
    "20121127-HIROSA-S-03",
    "20121127-HIROSA-S-17",
    "20121127-HIROSA-S-30",
    "20121127-HIROSA-S-44",
]


Samples = tuple[list[SubtaskSample], list[SubtaskSample]]


@pytest.fixture(scope="module")
def hiro_samples(hiro_data: Path) -> Samples:
    """Training and validation samples from the golden words of REAL trials."""
    root = hiro_data / REAL
    return load_samples([root / t for t in TRAIN], "golden"), load_samples(
        [root / t for t in VALID], "golden"
    )


@pytest.fixture(scope="module")
def sim_samples(sim_data: Path) -> Samples:
    """Training (4 trials) and validation (2 trials) samples from the engine's words of
    generated trials."""
    trials = find_trials([sim_data / SIM_SUCCESS])
    return load_samples(trials[:4], "engine"), load_samples(trials[4:6], "engine")


@pytest.fixture(scope="module", params=SOURCES)
def samples(request: pytest.FixtureRequest) -> Samples:
    """The REAL golden samples or the generated ones: the property tests run on both."""
    return request.getfixturevalue(f"{request.param}_samples")


@pytest.mark.parametrize(
    ("classifier", "encoding"),
    [
        ("svm", "compact"),
        ("mondrian", "compact"),
        ("svm", "paper"),
        ("svm-tuned", "compact"),
        ("forest", "words-wrench"),
        ("svm-forest", "words-wrench"),
    ],
)
def test_model_round_trips_through_the_safe_file(
    samples: Samples, tmp_path: Path, classifier: str, encoding: str
) -> None:
    train, valid = samples
    model = train_model(train, classifier, encoding, random_state=1)
    assert model.classes_ == ["approach", "insertion", "mating", "rotation"]
    proba = model.predict_proba_samples(valid)
    np.testing.assert_allclose(proba.sum(axis=1), 1.0)
    path = save_model(model, tmp_path / "model.npz")
    loaded = load_model(path, expect_encoding=encoding)
    assert (loaded.classifier, loaded.encoding, loaded.classes_) == (
        classifier,
        encoding,
        model.classes_,
    )
    np.testing.assert_allclose(loaded.predict_proba_samples(valid), proba)
    assert loaded.predict_samples(valid) == model.predict_samples(valid)


def test_the_default_names_finished_subtasks_by_the_forest_and_running_ones_by_the_vote(
    samples: Samples, tmp_path: Path
) -> None:
    """train_model's default: the verdict head is the forest, the running head the SVM + forest
    vote trained on prefixes too; both kinds survive the file."""
    train, valid = samples
    model = load_model(save_model(train_model(train), tmp_path / "model.rcbht"))
    assert model.classifier == "forest" and model.live is not None
    assert model.live.classifier == "svm-forest"
    assert model.estimator.n_estimators == VERDICT_TREES
    assert model.live.estimator.forest_.n_estimators == 100
    head = train_model(train, "svm-forest", running_prefixes=())
    assert head.live is None and head.classifier == "svm-forest"
    early = [prefix_sample(s, 0.25) for s in valid]
    prefixed = with_prefixes(train, RUNNING_PREFIXES["words-wrench"])
    vote = train_model(prefixed, "svm-forest", running_prefixes=())
    np.testing.assert_allclose(
        model.live.predict_proba_samples(early), vote.predict_proba_samples(early)
    )


@pytest.mark.shared_data
def test_near_empty_rotation_is_classified_right(hiro_samples: Samples) -> None:
    """REAL S-22..S-46 have a 5 ms rotation: both classifiers still name it."""
    train, valid = hiro_samples
    for classifier in ("svm", "mondrian"):
        model = train_model(train, classifier, "compact")
        short = [s for s in valid if s.duration < 0.05]
        assert short and all(s.subtask == "rotation" for s in short)
        assert model.predict_samples(short) == ["rotation"] * len(short)
        accuracy = np.mean(
            [p == s.subtask for p, s in zip(model.predict_samples(valid), valid, strict=True)]
        )
        assert accuracy >= 0.75, (classifier, accuracy)


def test_online_update_continues_from_a_loaded_forest(samples: Samples, tmp_path: Path) -> None:
    train, valid = samples
    model = train_model(train[:8], "mondrian", "compact")
    loaded = load_model(save_model(model, tmp_path / "mf.npz"))
    for model_ in (model, loaded):
        for start in range(8, len(train), 4):
            model_.partial_fit_samples(train[start : start + 4])
    # the stored random stream continues, so both forests grow identically
    np.testing.assert_allclose(
        model.predict_proba_samples(valid), loaded.predict_proba_samples(valid)
    )
    with pytest.raises(InputError, match="mondrian"):
        train_model(train, "svm", "compact").partial_fit_samples(train[:4])


def test_a_budgeted_forest_with_a_grown_class_set_round_trips(
    samples: Samples, tmp_path: Path
) -> None:
    """The budget and classes learned online survive the model file; the loaded forest keeps
    learning exactly as the saved one; a file written before budgets loads unbounded."""
    train, valid = samples
    model = train_model(train[:8], "mondrian", "compact", max_nodes=400, max_points=12)
    regrasp = [dataclasses.replace(s, subtask="regrasp") for s in valid[:2]]
    model.partial_fit_samples(regrasp)  # a name the model was not trained with
    assert "regrasp" in model.classes_
    loaded = load_model(save_model(model, tmp_path / "mf.npz"))
    assert loaded.classes_ == model.classes_
    assert (loaded.estimator.max_nodes, loaded.estimator.max_points) == (400, 12)
    assert loaded.estimator.get_params() == model.estimator.get_params()
    for model_ in (model, loaded):
        for start in range(8, len(train), 4):
            model_.partial_fit_samples(train[start : start + 4])
        assert model_.estimator.n_nodes_ <= 400 and model_.estimator.n_stored_points_ <= 12
    np.testing.assert_array_equal(
        model.predict_proba_samples(valid), loaded.predict_proba_samples(valid)
    )

    def before_budgets(header: dict, arrays: dict) -> None:
        del header["mondrian"]["max_nodes"], header["mondrian"]["max_points"]
        header["checksum"] = checksum(header, {k: v for k, v in arrays.items() if k != "header"})

    unbounded = train_model(train[:8], "mondrian", "compact")
    path = save_model(unbounded, tmp_path / "old.npz")
    old = load_model(_rewrite(path, tmp_path / "old_rewritten.npz", before_budgets))
    assert (old.estimator.max_nodes, old.estimator.max_points) == (None, None)
    np.testing.assert_array_equal(
        old.predict_proba_samples(valid), unbounded.predict_proba_samples(valid)
    )


def test_an_uncompressed_model_file_loads_the_same_and_is_checked(
    samples: Samples, tmp_path: Path
) -> None:
    """The teach file is written uncompressed (rewritten at every teach, read by the live
    node): the same model, the same checks."""
    train, valid = samples
    model = train_model(train[:8], "mondrian", "compact")
    packed = save_model(model, tmp_path / "packed.npz")
    plain = save_model(model, tmp_path / "plain.npz", compress=False)
    assert plain.stat().st_size > packed.stat().st_size
    np.testing.assert_array_equal(
        load_model(plain).predict_proba_samples(valid), model.predict_proba_samples(valid)
    )
    data = bytearray(plain.read_bytes())
    for where in (len(data) // 3, len(data) // 2, 2 * len(data) // 3):
        flipped = tmp_path / f"flipped{where}.npz"
        flipped.write_bytes(data[:where] + bytes([data[where] ^ 0xFF]) + data[where + 1 :])
        with pytest.raises(InputError) as info:
            load_model(flipped)
        assert "\n" not in str(info.value) and str(flipped) in str(info.value)


def _rewrite(path: Path, out: Path, edit) -> Path:
    with np.load(path, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    header = json.loads(arrays["header"].tobytes())
    edit(header, arrays)
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    np.savez(out, **arrays)
    return out


@pytest.mark.parametrize("classifier", ["svm", "mondrian"])
def test_bad_model_files_give_one_line_errors(
    samples: Samples, tmp_path: Path, classifier: str
) -> None:
    train, _ = samples
    path = save_model(train_model(train, classifier, "compact"), tmp_path / "m.npz")

    def tamper(header: dict, arrays: dict) -> None:
        name = "svm_skops" if classifier == "svm" else "mf_threshold"
        value = arrays[name].copy()
        value[len(value) // 2] += 1
        arrays[name] = value

    def version(header: dict, arrays: dict) -> None:
        header["format_version"] = 99

    def relabel(header: dict, arrays: dict) -> None:
        header["classes"] = ["a", "b", "c", "d"]

    cases = {
        "checksum": _rewrite(path, tmp_path / "tampered.npz", tamper),
        "format version 99": _rewrite(path, tmp_path / "version.npz", version),
        "checksum mismatch": _rewrite(path, tmp_path / "relabel.npz", relabel),
    }
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    cases["not a readable model file"] = truncated
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"not a zip at all")
    cases["not a readable model file "] = garbage
    for expected, bad in cases.items():
        with pytest.raises(InputError) as info:
            load_model(bad)
        message = str(info.value)
        assert expected.strip() in message and "\n" not in message and str(bad) in message
    with pytest.raises(InputError, match="expected 'paper'"):
        load_model(path, expect_encoding="paper")
    with pytest.raises(InputError, match="not found"):
        load_model(tmp_path / "missing.npz")


STIFF = dataclasses.replace(
    default_config(),
    profile="stiff_sensor",
    window=7,
    fit_threshold=0.95,
    fit_noise_floor={"Fz": 0.02},
    calibrated_thresholds={"Fz": (90.0, 60.0, 30.0, 2.0, -2.0, -30.0, -60.0, -90.0)},
)
"""A profile as `rcbht calibrate` writes one: another window, fit rule, noise floor, Fz spectrum."""


@pytest.fixture(scope="module")
def stiff_model(sim_samples: Samples, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A model file trained with STIFF (and a running head)."""
    train, _ = sim_samples
    model = train_model(train, "svm", "compact", running_prefixes=(0.5,), taxonomy=STIFF)
    return save_model(model, tmp_path_factory.mktemp("stiff") / "stiff.rcbht")


def test_the_model_file_carries_the_profile_it_was_trained_with(
    stiff_model: Path, tmp_path: Path
) -> None:
    """The profile is embedded (running head too) and labels the model's words unless another is
    given, which is refused; a file without it (older) records only name and digest."""
    loaded = load_model(stiff_model)
    assert loaded.taxonomy == STIFF and loaded.live is not None and loaded.live.taxonomy == STIFF
    assert (loaded.taxonomy_profile, loaded.taxonomy_sha256) == (
        "stiff_sensor",
        taxonomy_digest(STIFF),
    )
    assert model_taxonomy(loaded) == STIFF == model_file_taxonomy(stiff_model)
    renamed = dataclasses.replace(STIFF, profile="other")  # the same values: the same words
    assert model_file_taxonomy(stiff_model, renamed) == renamed
    for refuse in (lambda: model_taxonomy(loaded, default_config(), stiff_model),
                   lambda: model_file_taxonomy(stiff_model, default_config())):  # fmt: skip
        with pytest.raises(InputError) as info:
            refuse()
        message = str(info.value)
        assert message.startswith(f"{stiff_model}: the model was trained on words of taxonomy "
                                  "profile 'stiff_sensor'") and "\n" not in message  # fmt: skip

    def older(header: dict, arrays: dict) -> None:
        del header["taxonomy"], header["live"]["taxonomy"]
        header["checksum"] = checksum(header, {k: v for k, v in arrays.items() if k != "header"})

    old = _rewrite(stiff_model, tmp_path / "old.npz", older)
    assert load_model(old).taxonomy is None
    assert load_model(old).taxonomy_sha256 == taxonomy_digest(STIFF)
    assert model_file_taxonomy(old, STIFF) == STIFF
    with pytest.raises(InputError, match="trained on words of taxonomy profile 'stiff_sensor'"):
        model_file_taxonomy(old)  # the reference profile: not the one it was trained with


@pytest.mark.parametrize(
    ("values", "expected"),
    [
        ({"window": 0}, "field taxonomy.window: must be >= 1, got 0"),
        ({"fit_threshold": "high"}, "field taxonomy.fit_threshold: expected a number, got 'high'"),
        ({"calibrated_thresholds": {"Fz": [1.0, 2.0]}},
         "field taxonomy.calibrated_thresholds.Fz: expected 8 values, got 2"),
        ({"shiny": True}, "field taxonomy.shiny: unknown key"),
        ({"fit_threshold": 0.5}, "field taxonomy: the embedded taxonomy profile 'stiff_sensor' "
                                 "does not have the recorded digest"),
    ],
)  # fmt: skip
def test_a_tampered_embedded_profile_is_a_one_line_error(
    stiff_model: Path, tmp_path: Path, values: dict, expected: str
) -> None:
    """A bad value or a profile changed behind its digest, in a file whose checksum was
    rewritten to match: refused by the loader and by the header-only reader alike."""

    def tamper(header: dict, arrays: dict) -> None:
        header["taxonomy"].update(values)
        header["checksum"] = checksum(header, {k: v for k, v in arrays.items() if k != "header"})

    bad = _rewrite(stiff_model, tmp_path / "bad.npz", tamper)
    for read in (load_model, model_file_taxonomy):
        with pytest.raises(InputError) as info:
            read(bad)
        message = str(info.value)
        assert message.startswith(f"{bad}, {expected}") and "\n" not in message, message


@pytest.mark.parametrize(
    ("dataset", "trial", "source", "subtasks"),
    [  # a SIM trial of the shared set with golden words, and a generated jammed trial
        pytest.param("SIM_HIRO_ONE_SA_SUCCESS", "20160911-2136-SideApproach-S", "golden",
                     ["approach", "rotation"], marks=pytest.mark.shared_data, id="hiro"),
        pytest.param(SIM_FAILURE, SIM_JAMMED, "engine", ["approach", "rotation", "insertion"],
                     id="sim"),
    ],
)  # fmt: skip
def test_trials_with_missing_subtasks_are_marked_incomplete(
    request: pytest.FixtureRequest, dataset: str, trial: str, source: str, subtasks: list[str]
) -> None:
    loaded = load_trials([dataset_root(request, dataset) / trial])[0]
    assert loaded.source == source and not loaded.complete
    assert [s.subtask for s in loaded.samples] == subtasks


def test_unknown_word_source_and_missing_input(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="word source"):
        load_samples([tmp_path], "magic")
    with pytest.raises(InputError):
        load_samples([tmp_path / "nowhere"])


@pytest.mark.shared_data
def test_engine_words_give_the_same_samples_as_golden(hiro_data: Path) -> None:
    """words='engine' (batch RCBHT on the wrench) splits into the same sub-task words."""
    trial = hiro_data / REAL / "20121127-HIROSA-S-30"
    engine, golden = load_samples([trial], "engine"), load_samples([trial], "golden")
    from rcbht_introspection.grammar.encoding.compact import compact_raw_features

    assert [(s.subtask, s.start, s.end) for s in engine] == [
        (s.subtask, s.start, s.end) for s in golden
    ]
    for ours, theirs in zip(engine, golden, strict=True):
        a, b = compact_raw_features(ours, ["R"]), compact_raw_features(theirs, ["R"])
        assert set(a) == set(b)
        # golden files hold 5 decimals
        assert max(abs(a[k] - b[k]) for k in a) < 1e-4


def test_prefix_augmentation_adds_the_prefixes_as_training_samples(samples: Samples) -> None:
    train, valid = samples
    model = train_model(train, "mondrian", "compact", augment_prefixes=(0.5,))
    assert len(model.estimator._y) == 2 * len(train)
    from rcbht_introspection.grammar.split import prefix_sample

    halves = [prefix_sample(s, 0.5) for s in valid]
    assert all(
        h.end - h.start == pytest.approx(0.5 * s.duration)
        for h, s in zip(halves, valid, strict=True)
    )
    assert model.predict_proba_samples(halves).shape == (len(valid), 4)

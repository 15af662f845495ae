"""`rcbht calibrate` (taxonomy/calibration.py): a profile for a noisy 100 Hz sensor, made at test
time, where the default profile cuts a primitive at almost every window; the profile file's
round trip; its use by label, train, the live stream factory; the model file that carries it to
live-eval and segmenter_node; and HIRO kept close."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import REAL

from rcbht_introspection.cli import main
from rcbht_introspection.config_files import write_profile
from rcbht_introspection.configure.params import (
    SegmenterConfig,
    config_from_parameters,
    defaults,
    segmenter_taxonomy,
)
from rcbht_introspection.errors import InputError
from rcbht_introspection.io.hiro import find_trials, read_trial, write_trial
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.learn.data import load_trial_samples
from rcbht_introspection.learn.model_file import load_model
from rcbht_introspection.live.segmenter import arm_stream_factory
from rcbht_introspection.taxonomy.batch import label_trial
from rcbht_introspection.taxonomy.calibration import (
    MAX_CUT_FRACTION,
    Calibration,
    calibrate_profile,
    compare_profiles,
    profile_stats,
)
from rcbht_introspection.taxonomy.config import (
    default_config,
    load_taxonomy_config,
    taxonomy_digest,
    write_taxonomy_config,
)
from rcbht_introspection.taxonomy.primitives import axis_thresholds, gradient_spectrum
from rcbht_introspection.taxonomy.stream import label_trial_streamed
from rcbht_introspection.taxonomy.words import AXES, Level

PHASES = (0.0, 2.0, 3.5, 5.5)
"""Sub-task starts (s) of a generated trial: approach, rotation, insertion, mating."""
END_S = 7.5
RATE_HZ = 100.0
NOISE = np.array([0.6, 0.6, 0.6, 0.03, 0.03, 0.03])
"""White noise std per axis (N, Nm): a noisy F/T sensor, far above HIRO's."""


def noisy_trial(seed: int) -> Trial:
    """A HIRO-like trial at 100 Hz: piecewise-linear wrench (quiet approach, an impact-like edge
    in insertion) with heavy white noise, and ~11 % of the readings repeated (~89 Hz distinct)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, END_S, 1.0 / RATE_HZ)
    scale = np.array([8.0, 8.0, 8.0, 0.5, 0.5, 0.5])
    wrench = np.empty((len(t), len(AXES)))
    for a in range(len(AXES)):
        knots = np.sort(np.concatenate([PHASES, [END_S], rng.uniform(0, END_S, 8)]))
        values = rng.normal(0.0, scale[a], len(knots))
        values[knots < PHASES[1]] = rng.normal(0.0, 0.1 * scale[a])
        wrench[:, a] = np.interp(t, knots, values)
    ramp = np.clip((t - PHASES[2] - rng.uniform(0.3, 1.0)) / 0.05, 0.0, 1.0)
    wrench[:, 2] -= 25.0 * ramp
    wrench[:, 3] += 1.5 * ramp
    wrench += rng.normal(size=wrench.shape) * NOISE
    held = np.flatnonzero(rng.random(len(t)) < 0.11)
    for i in held[held > 0]:
        wrench[i] = wrench[i - 1]
    return Trial(f"noisy-{seed:02d}", t, {"R": wrench}, PHASES)


@pytest.fixture(scope="module")
def trials() -> list[Trial]:
    return [noisy_trial(seed) for seed in range(6)]


@pytest.fixture(scope="module")
def calibration(trials: list[Trial]) -> Calibration:
    return calibrate_profile(trials, "noisy_sensor")


@pytest.fixture(scope="module")
def dataset(trials: list[Trial], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The generated trials as HIRO-layout folders (what `rcbht calibrate/label/train` read)."""
    root = tmp_path_factory.mktemp("noisy") / "NOISY_SENSOR"
    for trial in trials:
        write_trial(trial, root / trial.name)
    return root


@pytest.fixture(scope="module")
def calibrated_model(
    dataset: Path, calibration: Calibration, tmp_path_factory: pytest.TempPathFactory
) -> tuple[Path, Path]:
    """The calibrated profile's file, and the model `rcbht train --taxonomy-config` makes with it."""
    folder = tmp_path_factory.mktemp("calibrated_model")
    profile = write_taxonomy_config(calibration.config, folder / "robot.yaml")
    model = folder / "model.rcbht"
    train = ["train", str(dataset), "--out", str(model), "--no-live-augment"]
    assert main([*train, "--taxonomy-config", str(profile)]) == 0
    return profile, model


# --------------------------------------------------------------------------- the table


def test_the_default_profile_cuts_at_almost_every_window_and_the_calibrated_one_does_not(
    trials: list[Trial], calibration: Calibration
) -> None:
    table = compare_profiles(trials, default_config(), calibration.config)
    before, after = table.before, table.after
    for axis in AXES:
        assert before.primitives_per_window[axis] > 0.85, axis
        assert after.primitives_per_window[axis] <= MAX_CUT_FRACTION, axis
    for axis in ("Fx", "Fy", "Fz"):  # noise: the default's spos of 1 N/s is never near-constant
        assert before.const_share[axis] < 0.2, axis
        assert 0.3 < after.const_share[axis] < 0.8, axis
    assert after.words_per_second["all"] < 0.6 * before.words_per_second["all"]
    assert calibration.config.window == 5  # 25 ms at 100 Hz is 2.5 samples: never below 5
    assert calibration.rate_hz == pytest.approx(RATE_HZ)
    assert set(calibration.config.fit_noise_floor or {}) == set(AXES)
    assert calibration.notes == []


def test_the_spectra_come_from_the_segment_gradients(calibration: Calibration) -> None:
    spectra = calibration.config.calibrated_thresholds or {}
    for axis in AXES:
        pimp, pconst = calibration.limits[axis]
        assert 0 < pconst < pimp
        assert spectra[axis] == pytest.approx(gradient_spectrum(pimp, pconst), rel=1e-3)
    # forces and moments share one spectrum each; the moments' is far smaller (units and motion)
    assert spectra["Fx"] == spectra["Fy"] == spectra["Fz"]
    assert spectra["Mx"] == spectra["My"] == spectra["Mz"]
    assert spectra["Mx"][0] < spectra["Fx"][0] / 5
    # measured spectra carry each axis's scale: the moment-domain rule is off
    assert calibration.config.domain_axes == ()


def test_stream_and_batch_agree_under_a_calibrated_profile(
    trials: list[Trial], calibration: Calibration
) -> None:
    config = calibration.config
    for trial in trials[:2]:
        assert label_trial_streamed(trial, config).words == label_trial(trial, config).words


def test_a_zero_noise_floor_is_the_original_fit_test(trials: list[Trial]) -> None:
    zero = dataclasses.replace(default_config(), fit_noise_floor=dict.fromkeys(AXES, 0.0))
    assert label_trial(trials[0], zero).words == label_trial(trials[0]).words


def test_a_dead_axis_group_keeps_the_default_thresholds(trials: list[Trial]) -> None:
    dead = [
        dataclasses.replace(
            t, wrench={"R": np.column_stack([t.wrench["R"][:, :3], np.zeros((len(t.time), 3))])}
        )
        for t in trials[:2]
    ]
    calibration = calibrate_profile(dead, "forces_only")
    spectra = calibration.config.calibrated_thresholds or {}
    for axis in ("Mx", "My", "Mz"):
        assert spectra[axis] == default_config().gradient_thresholds
    assert [n.split(":")[0] for n in calibration.notes] == ["Mx", "My", "Mz"]
    assert spectra["Fx"] != default_config().gradient_thresholds


# --------------------------------------------------------------------------- domain rule


def test_a_calibrated_spectrum_under_a_small_domain_keeps_spos(calibration: Calibration) -> None:
    """GradientClassification.m: with calibration files, any axis whose domain is below 1.9
    uses computeGradientSpectrum(pimp / 10, spos); the defaults divide all eight values."""
    fx = (40.0, 27.0, 14.0, 1.0, -1.0, -14.0, -27.0, -40.0)
    original = dataclasses.replace(
        default_config(), calibrated_thresholds={"Fx": fx}, domain_axes=AXES
    )
    assert axis_thresholds("Fx", 1.0, original) == gradient_spectrum(4.0, 1.0)
    assert axis_thresholds("Fx", 2.0, original) == fx
    assert axis_thresholds("Mx", 1.0, original) == tuple(
        v / 10 for v in (70, 46, 23, 1, -1, -23, -46, -70)
    )


# --------------------------------------------------------------------------- the profile file


def test_the_profile_file_round_trips(calibration: Calibration, tmp_path: Path) -> None:
    path = write_taxonomy_config(calibration.config, tmp_path / "robot.yaml", header="a header")
    assert path.read_text().startswith("# a header\n")
    assert load_taxonomy_config("noisy_sensor", path) == calibration.config
    assert load_taxonomy_config(None, path) == calibration.config  # the file's only profile
    assert taxonomy_digest(load_taxonomy_config(None, path)) == taxonomy_digest(calibration.config)


def test_a_file_of_several_profiles_needs_a_name(tmp_path: Path) -> None:
    path = write_profile(tmp_path / "two.yaml", "a", default_config(), omit=("profile",))
    text = path.read_text().replace("profiles:\n", "profiles:\n  b: {window: 7}\n")
    path.write_text(text)
    with pytest.raises(InputError, match=r"expected one taxonomy profile, found: b, a"):
        load_taxonomy_config(None, path)
    assert load_taxonomy_config("b", path).window == 7


def test_a_bad_noise_floor_names_its_line(calibration: Calibration, tmp_path: Path) -> None:
    path = write_taxonomy_config(calibration.config, tmp_path / "robot.yaml")
    text = path.read_text()
    path.write_text(
        text.replace(
            "    fit_noise_floor:\n      Fx:", "    fit_noise_floor:\n      Fx: -1.0\n      Fq:", 1
        )
    )
    with pytest.raises(InputError) as err:
        load_taxonomy_config(None, path)
    line = text.splitlines().index("    fit_noise_floor:") + 2
    field = "profiles.noisy_sensor.fit_noise_floor.Fx"
    assert str(err.value) == f"{path}, line {line}, field {field}: must be >= 0, got -1.0"


def test_the_live_stream_factory_loads_a_calibrated_file(
    trials: list[Trial], calibration: Calibration, tmp_path: Path
) -> None:
    path = write_taxonomy_config(calibration.config, tmp_path / "robot.yaml")
    stream = arm_stream_factory("noisy_sensor", str(path))("R")
    assert stream.config == calibration.config
    trial = trials[1]
    words = [w for s in trial.state_times for w in stream.mark_boundary(s)]
    words += stream.push_many(trial.time, trial.wrench["R"]) + stream.finish()
    batch = label_trial(trial, calibration.config)
    streamed = [w for w in words if w.level == Level.PRIMITIVE and w.axis == "Fx"]
    assert streamed == batch.axis_words("R", Level.PRIMITIVE, "Fx")


# --------------------------------------------------------------------------- the CLI


def test_rcbht_calibrate_writes_the_profile_and_the_report(
    dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out, report = tmp_path / "my_robot.yaml", tmp_path / "report.json"
    assert main(["calibrate", str(dataset), "--out", str(out), "--report", str(report)]) == 0
    printed = capsys.readouterr().out
    assert "primitives per window" in printed and "wrote profile 'my_robot'" in printed
    data = json.loads(report.read_text())
    loaded = load_taxonomy_config(None, out)
    assert loaded.profile == data["profile"] == "my_robot"
    assert loaded.window == data["window"]
    assert loaded.fit_noise_floor == data["fit_noise_floor"]
    assert {k: list(v) for k, v in (loaded.calibrated_thresholds or {}).items()} == data[
        "calibrated_thresholds"
    ]
    trials = [read_trial(f) for f in find_trials([dataset])]
    assert data["after"] == dataclasses.asdict(profile_stats(trials, loaded))
    assert data["before"] == dataclasses.asdict(profile_stats(trials, default_config()))
    assert len(data["inputs"]) == len(trials)


def test_label_and_train_take_the_calibrated_file(
    dataset: Path, calibration: Calibration, calibrated_model: tuple[Path, Path], tmp_path: Path
) -> None:
    profile, model = calibrated_model
    folder = find_trials([dataset])[0]
    out = tmp_path / "words"
    args = ["label", str(folder), "--out", str(out), "--format", "jsonl"]
    assert main([*args, "--taxonomy-config", str(profile)]) == 0
    records = [json.loads(line) for line in (out / folder.name / "words.jsonl").open()]
    expected = label_trial(read_trial(folder), calibration.config)
    n = sum(len(expected.axis_words("R", Level.PRIMITIVE, a)) for a in AXES)
    assert sum(r["level"] == "primitive" for r in records) == n

    trained = load_model(model)  # `rcbht train --taxonomy-config`: the fixture
    assert trained.taxonomy_profile == "noisy_sensor"
    assert trained.taxonomy_sha256 == taxonomy_digest(calibration.config)
    assert trained.taxonomy == calibration.config  # the whole profile travels in the file
    assert trained.live is not None and trained.live.taxonomy == calibration.config

    curve = tmp_path / "curve.json"
    evaluate = ["evaluate", str(dataset), "--permutations", "1", "--validation-trials", "2"]
    evaluate += ["--no-peers"]  # the profile is what is checked, not the peer column
    evaluate += ["--no-progress", "--json", str(curve), "--taxonomy-config", str(profile)]
    assert main(evaluate) == 0
    assert json.loads(curve.read_text())["taxonomy_profile"] == "noisy_sensor"


def test_live_eval_labels_with_the_profile_the_model_carries(
    dataset: Path,
    calibrated_model: tuple[Path, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """`rcbht live-eval --model` without a profile option replays the held-out trial as with the
    calibrated profile's file given; another profile is refused, in one line."""
    profile, model = calibrated_model
    args = ["live-eval", str(dataset), "--held-out", "1", "--model", str(model)]
    args += ["--mode", "boundary"]
    runs = {}
    for name, given in (("carried", []), ("given", ["--taxonomy-config", str(profile)])):
        out = tmp_path / f"{name}.json"
        assert main([*args, *given, "--json", str(out)]) == 0
        runs[name] = json.loads(out.read_text())
    assert {run["taxonomy_profile"] for run in runs.values()} == {"noisy_sensor"}
    carried, given = (runs[k]["results"]["model/boundary"] for k in ("carried", "given"))
    assert carried["timelines"] == given["timelines"]
    assert carried["time_accuracy"] == given["time_accuracy"] > 0
    capsys.readouterr()
    assert main([*args, "--profile", "reference"]) == 2
    err = capsys.readouterr().err.strip()
    assert "trained on words of taxonomy profile 'noisy_sensor'" in err and "\n" not in err, err


def test_segmenter_node_takes_the_profile_from_its_model_file(
    calibration: Calibration, calibrated_model: tuple[Path, Path]
) -> None:
    """segmenter_node's taxonomy parameters: the model file alone gives the profile it carries,
    the same profile named beside it too; another profile is refused naming the file."""
    profile, model = calibrated_model

    def labels_with(**parameters: str) -> object:
        values = {**defaults(SegmenterConfig), **parameters}
        return segmenter_taxonomy(config_from_parameters(SegmenterConfig, values))

    assert labels_with(taxonomy_model_file=str(model)) == calibration.config
    both = {"taxonomy_model_file": str(model), "taxonomy_config_file": str(profile)}
    assert labels_with(**both) == calibration.config
    assert labels_with(taxonomy_config_file=str(profile)) == calibration.config
    assert labels_with() == default_config()
    with pytest.raises(InputError) as info:
        labels_with(taxonomy_model_file=str(model), taxonomy_profile="reference")
    message = str(info.value)
    assert message.startswith(f"{model}: the model was trained on words of taxonomy profile "
                              "'noisy_sensor'") and "\n" not in message  # fmt: skip


def test_golden_words_are_the_reference_profiles_only(
    dataset: Path, calibration: Calibration
) -> None:
    folder = find_trials([dataset])[0]
    with pytest.raises(InputError, match="golden label files hold the reference profile's words"):
        load_trial_samples(folder, "golden", calibration.config)
    assert load_trial_samples(folder, "auto", calibration.config).source == "engine"


# --------------------------------------------------------------------------- HIRO


@pytest.mark.shared_data
def test_calibrating_on_real_hiro_keeps_the_reference_words(
    hiro_data: Path, tmp_path: Path
) -> None:
    """The reference fits HIRO (segmentation, 'cons' shares): the calibrated profile keeps its
    spectra and domain rule, so it gives the original code's words (golden files, two trials)."""
    report = tmp_path / "report.json"
    args = ["calibrate", str(hiro_data / REAL), "--out", str(tmp_path / "hiro.yaml")]
    assert main([*args, "--report", str(report)]) == 0
    data = json.loads(report.read_text())
    # HIRO is already in its own range: the window and the fit test stay the original's
    assert data["window"] == 5 and data["fit_noise_floor"] is None
    assert data["after"]["primitives_per_window"] == data["before"]["primitives_per_window"]
    assert data["calibrated_thresholds"] == {} and data["agreement"] == {
        "primitive": 1.0,
        "composition": 1.0,
        "behavior": 1.0,
    }
    from rcbht_introspection.io.conformance import compare_arms
    from rcbht_introspection.io.hiro import read_trial
    from rcbht_introspection.taxonomy.batch import label_trial
    from rcbht_introspection.taxonomy.config import load_taxonomy_config

    calibrated = load_taxonomy_config(None, tmp_path / "hiro.yaml")
    for name in ("20121127-HIROSA-S-01", "20121127-HIROSA-S-33"):
        folder = hiro_data / REAL / name
        words = label_trial(read_trial(folder), calibrated)
        assert [d for *_, d in compare_arms(folder, words) if d] == [], name

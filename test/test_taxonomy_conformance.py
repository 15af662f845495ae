"""Exact conformance of the batch engine with the published golden RCBHT outputs (spec section 2)."""

from __future__ import annotations

from pathlib import Path

import pytest

from rcbht_introspection.cli import main
from rcbht_introspection.io.conformance import compare_arms, first_difference
from rcbht_introspection.io.hiro import find_trials, read_trial
from rcbht_introspection.io.rcbht_format import level_path, read_records, read_words
from rcbht_introspection.taxonomy.batch import label_trial
from rcbht_introspection.taxonomy.words import AXES, Level

pytestmark = pytest.mark.shared_data


@pytest.mark.parametrize("dataset", ["REAL_HIRO_ONE_SA_SUCCESS", "SIM_HIRO_ONE_SA_SUCCESS"])
def test_every_composites_and_llbehaviors_file_is_identical(hiro_data: Path, dataset: str) -> None:
    trials = find_trials([hiro_data / dataset])
    assert trials
    diffs = []
    total = 0
    for folder in trials:
        for _, level, axis, diff in compare_arms(folder, label_trial(read_trial(folder))):
            total += 1
            if diff is not None:
                diffs.append(f"{folder.name} {level.value} {axis}: {diff}")
    assert total == 2 * len(AXES) * len(trials)
    assert diffs == []


def golden_segments(path: Path) -> list[dict[str, str]]:
    """The last run of a golden Segments file (it may hold several appended runs)."""
    records = read_records(path)
    starts = [i for i, r in enumerate(records) if r["Iteration"] == "1"]
    return records[starts[-1] :] if starts else records


@pytest.mark.parametrize(
    "trial",
    [
        "REAL_HIRO_ONE_SA_SUCCESS/20121127-HIROSA-S-01",
        "REAL_HIRO_ONE_SA_SUCCESS/20121127-HIROSA-S-05",
        "REAL_HIRO_ONE_SA_SUCCESS/20121127-HIROSA-S-33",
        "SIM_HIRO_ONE_SA_SUCCESS/20160911-2136-SideApproach-S",
    ],
)
def test_primitives_equal_the_golden_segments(hiro_data: Path, trial: str) -> None:
    folder = hiro_data / trial
    if not folder.is_dir():  # the SIM trial name differs between data releases
        folder = find_trials([hiro_data / trial.split("/")[0]])[0]
    words = label_trial(read_trial(folder))
    keys = ("Average", "Max Val", "Min Val", "Start", "Finish", "Gradient")
    for axis in AXES:
        ours = words.axis_words("R", Level.PRIMITIVE, axis)
        golden = golden_segments(level_path(folder / "golden", Level.PRIMITIVE, axis))
        assert len(ours) == int(golden[-1]["Iteration"])
        for record in golden:
            word = ours[int(record["Iteration"]) - 1]
            assert word.label == record["Grad Label"]
            for key in keys:
                assert word.features[key] == pytest.approx(float(record[key]), abs=1.5e-5), key


def test_rcbht_label_output_diffs_clean_against_golden(hiro_data: Path, tmp_path: Path) -> None:
    trials = find_trials([hiro_data / "REAL_HIRO_ONE_SA_SUCCESS"])[:3]
    assert main(["label", *map(str, trials), "--out", str(tmp_path)]) == 0
    for folder in trials:
        for level in (Level.COMPOSITION, Level.BEHAVIOR):
            for axis in AXES:
                ours = read_words(level_path(tmp_path / folder.name, level, axis), level, axis)
                golden = read_words(level_path(folder / "golden", level, axis), level, axis)
                assert first_difference(ours, golden) is None
        assert level_path(tmp_path / folder.name, Level.PRIMITIVE, "Mz").is_file()


def test_conformance_command_reports_and_fails_on_a_difference(
    hiro_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import shutil

    source = find_trials([hiro_data / "REAL_HIRO_ONE_SA_SUCCESS"])[0]
    dataset = tmp_path / "set"
    shutil.copytree(source, dataset / source.name)
    assert main(["conformance", str(dataset)]) == 0
    out = capsys.readouterr().out
    assert "Composites: 6/6 files identical" in out and "llBehaviors: 6/6" in out
    # change one golden label: the command must name the file and record, and exit 1
    path = level_path(dataset / source.name / "golden", Level.COMPOSITION, "Fy")
    text = path.read_text().replace("Label         : k", "Label         : d", 1)
    path.write_text(text)
    assert main(["conformance", str(dataset)]) == 1
    out = capsys.readouterr().out
    assert "Composites: 5/6 files identical" in out
    assert f"DIFF {source.name} composition Fy: record" in out


@pytest.mark.parametrize(
    "trial", ["20160930-HIRO_ERROR-02", "20160930-HIRO_ERROR-03", "20160930-HIRO_ERROR-04"]
)
def test_failure_trials_made_by_the_reference_code_state(hiro_data: Path, trial: str) -> None:
    """These failure trials' Composites come from the reference code state (the others from a
    later one, profile error_charac); they exercise the one-sample segment rule."""
    folder = hiro_data / "REAL_HIRO_ONE_SA_ERROR_CHARAC" / trial
    diffs = [
        (level.value, axis, diff)
        for _, level, axis, diff in compare_arms(folder, label_trial(read_trial(folder)))
        if level is Level.COMPOSITION and diff is not None
    ]
    assert diffs == []

"""`rcbht label/conformance/plot` on generated trials, and one-line errors on malformed input."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rcbht_introspection.cli import main
from rcbht_introspection.io.hiro import read_trial, write_trial
from rcbht_introspection.io.rcbht_format import level_path, read_words
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.taxonomy.batch import label_trial
from rcbht_introspection.taxonomy.words import AXES, LEVELS, Level

REPO = Path(__file__).resolve().parents[1]


def make_trial(folder: Path, n: int = 1200, seed: int = 0) -> Path:
    """A synthetic one-arm trial: a smooth wrench with a few contacts, four sub-task starts."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.005
    base = np.stack([np.sin(t * (a + 1)) * (a + 1) for a in range(6)], axis=1)
    base[n // 2 :, 2] += 8.0
    wrench = base + np.cumsum(rng.normal(0, 0.02, (n, 6)), axis=0)
    trial = Trial(folder.name, t, {"R": wrench}, (0.0, t[n // 4], t[n // 2], t[3 * n // 4]))
    return write_trial(trial, folder)


def test_label_writes_the_original_layout_and_it_reads_back(tmp_path: Path) -> None:
    trial = make_trial(tmp_path / "in" / "T1")
    assert main(["label", str(trial), "--out", str(tmp_path / "out")]) == 0
    words = label_trial(read_trial(trial))
    for level in LEVELS:
        for axis in AXES:
            back = read_words(level_path(tmp_path / "out" / "T1", level, axis), level, axis)
            ours = words.axis_words("R", level, axis)
            assert [w.label for w in back] == [w.label for w in ours]
            assert [w.start for w in back] == pytest.approx([w.start for w in ours], abs=1e-5)


def test_label_a_dataset_folder_as_jsonl(tmp_path: Path) -> None:
    make_trial(tmp_path / "set" / "A", seed=1)
    make_trial(tmp_path / "set" / "B", seed=2)
    assert (
        main(["label", str(tmp_path / "set"), "--out", str(tmp_path / "o"), "--format", "jsonl"])
        == 0
    )
    for name in ("A", "B"):
        lines = (tmp_path / "o" / name / "words.jsonl").read_text().splitlines()
        records = [json.loads(line) for line in lines]
        assert {r["level"] for r in records} == {level.value for level in Level}
        assert {r["axis"] for r in records} == set(AXES)
        assert all(r["trial"] == name and r["start"] <= r["end"] for r in records)


def test_plot_writes_a_png(tmp_path: Path) -> None:
    trial = make_trial(tmp_path / "T")
    out = tmp_path / "plot.png"
    assert main(["plot", str(trial), "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


BAD_TABLES = {
    "columns": ("0 1 2 3 4 5 6\n0.005 1 2 3 4 5\n", "line 2", "expected 7 columns"),
    "number": ("0 1 2 3 4 5 6\n0.005 1 2 x 4 5 6\n", "line 2", "field Fz"),
    "nan": ("0 1 2 3 4 5 6\n0.005 1 2 3 nan 5 6\n", "line 2", "field Mx"),
    "time": ("0 1 2 3 4 5 6\n0.005 1 2 3 4 5 6\n0.005 1 2 3 4 5 6\n", "line 3", "field t"),
}


@pytest.mark.parametrize("case", sorted(BAD_TABLES))
def test_malformed_input_is_a_one_line_error_with_exit_2(
    tmp_path: Path, case: str, capsys: pytest.CaptureFixture[str]
) -> None:
    text, where, what = BAD_TABLES[case]
    folder = tmp_path / "bad"
    folder.mkdir()
    (folder / "R_Torques.dat").write_text(text)
    assert main(["label", str(folder), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err
    assert err.startswith("rcbht label: error: ") and "R_Torques.dat" in err
    assert where in err and what in err


@pytest.mark.parametrize(
    "argv",
    [
        ["label", "{tmp}/missing", "--out", "{tmp}/o"],
        ["label", "{trial}", "--out", "{tmp}/o", "--profile", "nope"],
        ["conformance", "{tmp}/set"],
        ["plot", "{tmp}/missing", "--out", "{tmp}/p.png"],
    ],
)
def test_bad_arguments_are_one_line_errors(tmp_path: Path, argv: list[str]) -> None:
    trial = make_trial(tmp_path / "set" / "T")
    args = [a.format(tmp=tmp_path, trial=trial) for a in argv]
    proc = subprocess.run(
        [sys.executable, "-m", "rcbht_introspection.cli", *args],
        capture_output=True, text=True, cwd=REPO, check=False,
    )  # fmt: skip
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "error: " in proc.stderr
    assert "Traceback" not in proc.stderr


def test_conformance_compares_both_arms_of_a_two_arm_trial(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A simulated two-arm trial with golden files written by the batch engine (golden/L, golden/R):
    identical; one changed label in L's files is found and named with its arm."""
    from rcbht_introspection.io.rcbht_format import write_trial_words
    from rcbht_introspection.sim import load_sim_config, simulate_trial

    trial = simulate_trial(load_sim_config(), 7, scenario="two-arm", name="TWO")
    folder = write_trial(trial, tmp_path / "set" / "TWO")
    write_trial_words(label_trial(read_trial(folder)), folder / "golden")
    assert main(["conformance", str(tmp_path / "set")]) == 0
    out = capsys.readouterr().out
    assert "Composites: 12/12 files identical" in out and "llBehaviors: 12/12" in out
    # change the first MC label of arm L's Fz file: only that file of that arm differs
    path = level_path(folder / "golden" / "L", Level.COMPOSITION, "Fz")
    ours = read_words(path, Level.COMPOSITION, "Fz")
    other = next(lb for lb in ("a", "i", "d", "k") if lb != ours[0].label)
    text = path.read_text()
    label_line = f"Label         : {ours[0].label}\n"
    assert label_line in text
    path.write_text(text.replace(label_line, f"Label         : {other}\n", 1))
    assert main(["conformance", str(tmp_path / "set")]) == 1
    out = capsys.readouterr().out
    assert (
        f"DIFF TWO L composition Fz: record 1: label {ours[0].label!r} != golden {other!r}" in out
    )
    assert "Composites: 11/12 files identical" in out and "llBehaviors: 12/12" in out
    # golden files of one arm only (R's, flat, as a one-arm trial has them): L differs everywhere
    shutil.rmtree(folder / "golden" / "L")
    for sub in (folder / "golden" / "R").iterdir():
        sub.rename(folder / "golden" / sub.name)
    assert main(["conformance", str(tmp_path / "set")]) == 1
    out = capsys.readouterr().out
    assert "DIFF TWO L behavior Mz: no golden files of arm L (golden/L/)" in out
    assert "Composites: 6/12 files identical" in out

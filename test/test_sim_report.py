"""Realism report: statistics against the real HIRO golden LLB files, and the report's outputs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from rcbht_introspection.cli import main as cli_main
from rcbht_introspection.sim import write_dataset
from rcbht_introspection.sim.realism import golden_words, set_stats
from rcbht_introspection.taxonomy.words import AXES

pytestmark = pytest.mark.shared_data


def test_real_golden_frequencies_are_distributions(hiro_data: Path) -> None:
    real = set_stats("real", hiro_data / "REAL_HIRO_ONE_SA_SUCCESS", golden_words)
    assert len(real.trials) == 46
    for subtask in ("approach", "insertion", "mating"):
        for axis in AXES:
            freqs = real.frequencies(subtask, axis)
            assert freqs.sum() == pytest.approx(1.0)
    # the published statistics: FX is the most common LLB of the real set (spec 4)
    assert np.argmax(real.frequencies("approach", "Fx")) == 0


def test_sim_report_writes_tables_and_figures(hiro_data: Path, tmp_path: Path) -> None:
    sim = tmp_path / "sim"
    write_dataset(sim, 4, seed=1)
    out = tmp_path / "report"
    code = cli_main(
        ["sim-report", str(sim), "--real", str(hiro_data / "REAL_HIRO_ONE_SA_SUCCESS"),
         "--out", str(out)]
    )  # fmt: skip
    assert code == 0
    for name in ("report.md", "report.json", "llb_frequencies.png", "variability.png",
                 "example_trials.png"):  # fmt: skip
        assert (out / name).stat().st_size > 0, name
    result = json.loads((out / "report.json").read_text())
    assert result["n_sim"] == 4 and result["n_real"] == 46
    assert 0.0 < result["mean_tv_distance"] < 0.4  # close to, but not a copy of, the real set


def test_sim_report_without_real_set_is_a_one_line_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli_main(["sim-report", str(tmp_path), "--real", str(tmp_path / "nope")]) == 2
    err = capsys.readouterr().err
    assert "real HIRO set not found" in err and len(err.strip().splitlines()) == 1

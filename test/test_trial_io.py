"""HIRO trial folders: real files load; malformed ones give a one-line error with file/line/field."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import SOURCES, trial_folders

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.hiro import read_trial, write_trial
from rcbht_introspection.io.trial import Trial


@pytest.mark.parametrize("source", SOURCES)
def test_recorded_trial_loads(request: pytest.FixtureRequest, source: str) -> None:
    """A REAL HIRO trial and a generated one load alike: one arm, six columns, four sub-tasks."""
    (folder,) = trial_folders(request, source, ["20121127-HIROSA-S-01"], [0])
    trial = read_trial(folder)
    assert trial.arms == ("R",)
    assert trial.wrench["R"].shape[1] == 6 and len(trial.time) == len(trial.wrench["R"])
    assert np.all(np.diff(trial.time) > 0)
    assert [name for name, _, _ in trial.subtask_bounds()] == [
        "approach", "rotation", "insertion", "mating",
    ]  # fmt: skip


def test_round_trip_two_arms(tmp_path: Path) -> None:
    time = np.arange(50) * 0.005
    rng = np.random.default_rng(0)
    trial = Trial(
        name="t",
        time=time,
        wrench={"L": rng.normal(size=(50, 6)), "R": rng.normal(size=(50, 6))},
        state_times=(0.0, 0.05, 0.1, 0.2),
    )
    write_trial(trial, tmp_path / "t")
    back = read_trial(tmp_path / "t")
    assert back.arms == ("L", "R")
    np.testing.assert_allclose(back.wrench["L"], trial.wrench["L"], atol=1e-5)
    assert back.state_times == pytest.approx(trial.state_times)


def test_bounds_without_state_times() -> None:
    trial = Trial(name="t", time=np.arange(3.0), wrench={"R": np.zeros((3, 6))})
    assert trial.subtask_bounds() == []


@pytest.mark.parametrize(
    ("row", "what"),
    [("0.01 1 2 3 4 5", "column"), ("0.01 1 2 x 4 5 6", "Fz"), ("0.01 1 2 nan 4 5 6", "Fz"),
     ("0.0 1 2 3 4 5 6", "time")],
)  # fmt: skip
def test_malformed_torques(tmp_path: Path, row: str, what: str) -> None:
    trial = tmp_path / "bad"
    trial.mkdir()
    (trial / "R_Torques.dat").write_text("0.0 1 2 3 4 5 6\n0.005 1 2 3 4 5 6\n" + row + "\n")
    (trial / "R_State.dat").write_text("0.0\n0.005\n")
    with pytest.raises(InputError) as info:
        read_trial(trial)
    message = str(info.value)
    assert "R_Torques.dat" in message and "line 3" in message
    assert what.lower() in message.lower()

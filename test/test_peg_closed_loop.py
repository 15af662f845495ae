"""The peg-in-hole task's failure family (the hole turned beyond the square peg's fit), its
stepped attempts (checked against the batch simulator) and `rcbht closed-loop --task peg`."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from rcbht_introspection.cli import main
from rcbht_introspection.errors import InputError
from rcbht_introspection.sim.peg_config import PegConfig, load_peg_config
from rcbht_introspection.sim.peg_episode import PegAttempt, PegWorld, draw_peg_world
from rcbht_introspection.sim.peg_simulate import (
    WRENCH_DEPARTURE,
    run_peg_physics,
    simulate_peg_trial,
)
from rcbht_introspection.sim.sensor import resample
from rcbht_introspection.verify.labels import label_of


@pytest.fixture(scope="module")
def peg() -> PegConfig:
    return load_peg_config()


@pytest.fixture(scope="module")
def turned(peg: PegConfig) -> PegWorld:
    world = draw_peg_world(peg, 31, "hole_yaw")
    assert world.failing
    return world


def test_a_turned_hole_fails_and_is_labelled_as_the_peg_s_offset_against_it(
    peg: PegConfig,
) -> None:
    trial = simulate_peg_trial(peg, 31, failure="hole_yaw")
    assert trial.outcome == "hole_yaw" and not trial.metadata["inserted"]
    record = trial.metadata["failure"]
    assert isinstance(record, dict) and record["onset_rule"] == WRENCH_DEPARTURE
    assert 0.0 < record["onset"] < trial.end_time
    yaw = record["deviation"]["yaw"]
    low, high = peg.failures.hole_yaw
    nominal = 4 * peg.variation.offset_yaw  # the hole's own small yaw error, four std
    assert low - nominal <= abs(yaw) <= high + nominal
    assert yaw * trial.metadata["hole_yaw_deg"] < 0  # the peg's offset: the hole's negated
    label = label_of(trial)
    assert label.failure_class == "hole_yaw" and label.directions() == {
        "x": "0",
        "y": "0",
        "r": "-" if yaw < 0 else "+",
    }
    nominal_trial = simulate_peg_trial(peg, 31)
    assert nominal_trial.outcome == "success" and "failure" not in nominal_trial.metadata


def test_an_unknown_peg_failure_names_its_field(peg: PegConfig, tmp_path: Path) -> None:
    with pytest.raises(InputError, match="unknown failure type 'tilt'"):
        simulate_peg_trial(peg, 1, failure="tilt")
    bad = tmp_path / "peg.yaml"
    bad.write_text("failures:\n  types: [hole_yaw, tilt]\n")
    with pytest.raises(InputError, match=r"failures\.types\[1\]"):
        load_peg_config(bad)


def test_a_stepped_peg_attempt_is_the_batch_physics_and_the_truth_inserts(
    peg: PegConfig, turned: PegWorld
) -> None:
    rate = peg.sensor.rate_hz
    attempt = PegAttempt(peg, turned, (0.0, 0.0, 0.0, 0.0), 0, rate)
    samples, events = [], []
    while (sample := attempt.step()) is not None:
        samples.append(sample.wrench)
        events += sample.events
    raw, state, inserted, _ = run_peg_physics(peg, turned.run.physics, turned.run.plan)
    true = resample(raw, round(1 / (rate * peg.physics.timestep)))[:, :6]
    assert state.aborted and not inserted
    assert attempt.end is not None and attempt.end.reason == "timeout"
    assert not attempt.end.latched and len(samples) == len(true)
    measured = np.asarray(samples)[:, :3]
    q = peg.sensor.quantization_force
    assert np.abs(measured - (true[:, :3] + attempt.errors[: len(true), :3])).max() <= q
    assert [n for _, n in events] == list(state.phases)
    corrected = PegAttempt(peg, turned, turned.truth, 1, rate)
    while corrected.step() is not None:
        pass
    assert corrected.end is not None and corrected.end.seated and corrected.end.latched
    mirrored = (0.0, 0.0, 0.0, -turned.truth[3])
    wrong = PegAttempt(peg, turned, mirrored, 2, rate)
    while wrong.step() is not None:
        pass
    assert wrong.end is not None and not wrong.end.latched
    assert math.isclose(abs(turned.truth[3]), abs(mirrored[3]))


def test_closed_loop_runs_the_peg_task_with_its_own_table(tmp_path: Path) -> None:
    out = tmp_path / "peg.json"
    recovery = tmp_path / "peg-recovery.yaml"  # the shipped table at a rate 40 successes calibrate
    shipped = Path(__file__).parents[1] / "config" / "recovery" / "peg.yaml"
    recovery.write_text(shipped.read_text().replace("abort_rate: 0.01 ", "abort_rate: 0.025"))
    args = ["closed-loop", "--task", "peg", "--trials", "2", "--nominal", "1"]
    args += ["--recovery", str(recovery)]
    assert main([*args, "--policy", "none,oracle", "--seed", "3", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["task"] == "peg" and result["classes"] == ["hole_yaw"]
    assert result["policies"]["none"]["success_within_attempts"]["3"] == 0.0
    assert result["policies"]["oracle"]["success_within_attempts"]["2"] == 1.0
    assert result["verifier"]["deviation_by_class"]["hole_yaw"]["size"]["r"] > 0
    assert result["verifier"]["successes"] == 40  # 1 / 0.025: the table's rate reached training
    assert main([*args, "--ros", str(tmp_path / "ros")]) == 2  # sim_node runs the snap task

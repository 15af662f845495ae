"""The closed loop offline: the simulated trial stepped attempt by attempt (checked against the
batch simulator), corrections that seat a failing world, and `rcbht closed-loop`'s JSON."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from rcbht_introspection.cli import main
from rcbht_introspection.closed_loop.run import run_trial
from rcbht_introspection.config_files import config_path
from rcbht_introspection.plan.recovery import load_recovery_config
from rcbht_introspection.sim import load_sim_config
from rcbht_introspection.sim.config import SimConfig
from rcbht_introspection.sim.episode import Attempt, World, draw_world
from rcbht_introspection.sim.sensor import resample
from rcbht_introspection.sim.simulate import run_physics

RATE = 200.0


@pytest.fixture(scope="module")
def cell() -> SimConfig:
    return load_sim_config(config_path("sim/cell.yaml"))


@pytest.fixture(scope="module")
def slipped(cell: SimConfig) -> World:
    """A world whose part slipped +x in the hand: the uncorrected task times out."""
    world = draw_world(cell, 4242, "deviation_x+")
    assert world.failing
    return world


def _run(cell: SimConfig, world: World, correction: tuple[float, ...], index: int) -> Attempt:
    attempt = Attempt(cell, world, (*correction,), index, RATE)  # type: ignore[arg-type]
    while attempt.step() is not None:
        pass
    return attempt


def test_an_uncorrected_attempt_is_the_batch_simulator_s_physics(
    cell: SimConfig, slipped: World
) -> None:
    """Stepped sample by sample, the wrench is the batch run's (box-averaged) plus the sensor's
    errors, within the sensor's quantum, and its sub-task events are the batch run's switches."""
    attempt = Attempt(cell, slipped, (0.0, 0.0, 0.0, 0.0), 0, RATE)
    samples, events = [], []
    while (sample := attempt.step()) is not None:
        samples.append(sample.wrench)
        events += sample.events
    batch = run_physics(cell, slipped.draw.physics, slipped.draw.plan, False)
    true = resample(batch.wrench, round(1 / (RATE * cell.physics.timestep)))[:, :6]
    assert batch.state.aborted and attempt.end is not None
    assert attempt.end.reason == "timeout" and not attempt.end.latched
    assert len(samples) == len(true)
    q = cell.sensor.quantization_force
    measured = np.asarray(samples)[:, :3]
    assert np.abs(measured - (true[:, :3] + attempt.errors[: len(true), :3])).max() <= q
    switches = [round(t, 9) for t in batch.state.switch_times]
    assert [t for t, _ in events] == pytest.approx(switches, abs=1 / RATE)
    assert [n for _, n in events] == ["approach", "rotation", "insertion"]


def test_the_true_correction_seats_the_part_and_an_abort_backs_off(
    cell: SimConfig, slipped: World
) -> None:
    corrected = _run(cell, slipped, slipped.truth, 1)
    assert corrected.end is not None and corrected.end.seated and corrected.end.latched
    aborted = Attempt(cell, slipped, (0.0, 0.0, 0.0, 0.0), 2, RATE)
    while aborted.time < 6.0:
        assert aborted.step() is not None
    aborted.abort()
    while aborted.step() is not None:
        pass
    end = aborted.end
    assert end is not None and end.reason == "aborted" and not end.seated
    assert 6.0 < end.duration < 6.0 + cell.controller.abort_time + 0.1
    assert end.return_s > 0.0


def test_a_world_that_seats_uncorrected_is_not_a_failing_one(cell: SimConfig) -> None:
    """A slip the arm's compliance absorbs (-x in the cell) is judged by where the part ends."""
    world = draw_world(cell, 4243, "deviation_x-")
    assert not world.failing
    assert _run(cell, world, (0.0, 0.0, 0.0, 0.0), 0).end.latched  # type: ignore[union-attr]


def test_policies_on_one_failing_world(cell: SimConfig, slipped: World) -> None:
    table = load_recovery_config("snap")
    none = run_trial(cell, slipped, "none", table, None)
    assert not none.success and len(none.attempts) == 1
    oracle = run_trial(cell, slipped, "oracle", table, None)  # no alarms: the arm's own failure
    assert oracle.success and len(oracle.attempts) == 2
    assert oracle.time_s == pytest.approx(
        sum(a.end.duration for a in oracle.attempts) + oracle.attempts[0].end.return_s
    )
    blind = run_trial(cell, slipped, "introspect", table, None)
    assert blind.policy == "introspect" and not blind.success
    assert [d["correction"] for d in blind.decisions if d["kind"] == "attempt"] == [
        {"x": 0.0, "y": 0.0, "z": 0.0, "yaw": 0.0}
    ] * table.max_attempts  # no verifier: it runs as retry


def test_closed_loop_command_writes_each_policy_s_figures(tmp_path: Path) -> None:
    out = tmp_path / "loop.json"
    code = main(
        ["closed-loop", "--trials", "2", "--nominal", "1", "--classes", "missed_snap,jamming",
         "--policy", "none,retry,search", "--json", str(out)]
    )  # fmt: skip
    assert code == 0
    result = json.loads(out.read_text())
    assert result["failing_trials"] == 2 and result["nominal_trials"] == 1
    for name in ("none", "retry", "search"):
        policy = result["policies"][name]
        assert set(policy["success_within_attempts"]) == {"1", "2", "3"}
        assert policy["unnecessary_aborts_per_nominal_trial"] == 0.0
        trials = policy["trials"]
        assert [t["class"] for t in trials] == ["jamming", "missed_snap", "nominal"]
        assert {"seed", "class", "attempts", "outcome"} <= set(trials[0])
    assert result["policies"]["none"]["success_within_attempts"]["3"] == 0.0
    assert max(t["attempts"] for t in result["policies"]["retry"]["trials"]) == 3


def test_closed_loop_refuses_an_unknown_policy(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["closed-loop", "--policy", "hope"]) == 2
    assert "unknown policy 'hope'" in capsys.readouterr().err

"""Collisions and slow slips of the simulated snap cell: their records (class, onset at the push's
or the slip's start, direction or final offset), the wrench they leave, the verifier's jump
features that see a push at the sensor's rate and the departure that sees a slip grow."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rcbht_introspection.config_files import config_path
from rcbht_introspection.errors import InputError
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.sim import SimConfig, load_sim_config, simulate_trial
from rcbht_introspection.sim.failures import failure_classes
from rcbht_introspection.sim.simulate import draw_trial
from rcbht_introspection.verify.config import load_verify_config
from rcbht_introspection.verify.detector import Detection, Detector
from rcbht_introspection.verify.features import (
    ArmFeatures,
    TrialFeatures,
    kind_columns,
    trial_features,
)
from rcbht_introspection.verify.labels import label_of


@pytest.fixture(scope="module")
def cell(tmp_path_factory: pytest.TempPathFactory) -> SimConfig:
    text = config_path("sim/cell.yaml").read_text()
    path = Path(tmp_path_factory.mktemp("cfg")) / "cell.yaml"
    path.write_text(text + "failures:\n  types: [collision, slip]\n")
    return load_sim_config(path)


def _jumps(trial: Trial) -> tuple[np.ndarray, np.ndarray]:
    """Tick times and the force axes' jump features of a trial's right arm."""
    feats = ArmFeatures(load_verify_config())
    rows = []
    for t, w in zip(trial.time, np.asarray(trial.wrench["R"]), strict=True):
        rows.extend(feats.push(float(t) - float(trial.time[0]), w))
    jumps = np.array([r[kind_columns("jump", 1)[:3]] for _, r in rows])
    return np.array([g for g, _ in rows]), jumps


def test_the_families_are_classes_of_their_own(cell: SimConfig) -> None:
    assert failure_classes(cell.failures) == ("collision", "slip")
    with pytest.raises(InputError, match="unknown failure type"):
        draw_trial(cell, np.random.default_rng(0), "meteor")


def test_a_collision_is_labelled_at_its_push_and_shows_as_a_jump(cell: SimConfig) -> None:
    trial = simulate_trial(cell, 4, failure="collision")
    record = trial.metadata["failure"]
    assert trial.outcome == "collision" and record["onset_rule"] == "pulse_start"
    assert record["phase"] in ("approach", "rotation", "insertion")
    assert 5.0 <= record["peak_force"] <= 40.0
    label = label_of(trial)
    assert label.failed and label.failure_class == "collision" and label.onset is not None
    assert label.directions() is not None  # the push's direction, for the direction heads
    times, jumps = _jumps(trial)
    before = jumps[(times > label.onset - 1.0) & (times < label.onset)].max()
    after = jumps[(times >= label.onset) & (times <= label.onset + 0.1)].max()
    assert after > 2.0 * before  # the push stands out of the sub-task's own jumps at once


def test_a_slip_is_labelled_at_its_start_with_its_final_offset(cell: SimConfig) -> None:
    trial = simulate_trial(cell, 6, failure="slip")
    record = trial.metadata["failure"]
    assert trial.outcome == "slip" and record["onset_rule"] == "slip_start"
    assert record["phase"] in ("rotation", "insertion")
    moved = {a: v for a, v in record["deviation"].items() if v != 0.0}
    assert len(moved) == 1  # one axis
    ((axis, size),) = moved.items()
    f = cell.failures
    low, high = f.deviation_yaw if axis == "yaw" else f.deviation_xy
    assert low <= abs(size) <= high
    assert 1.0 <= record["duration_s"] <= 4.0


def test_the_nominal_twin_of_a_disturbed_draw_is_undisturbed(cell: SimConfig) -> None:
    """A collision or a slip leaves the draw's physics as a nominal trial's: the twin that
    other failures' onsets compare with is the same world."""
    struck = draw_trial(cell, np.random.default_rng([3, 0]), "collision")
    assert struck.collision is not None and struck.slip is None
    assert struck.physics == struck.twin and struck.deviation.to_dict() == {
        "x": 0.0,
        "y": 0.0,
        "yaw": 0.0,
    }


def test_a_jump_is_a_departure_from_an_earlier_step_and_repeats_do_not_make_one() -> None:
    """A step of 5 N in Fx shows in full in the tick that holds it; a sensor that repeats its
    last sample (and a constant bias) adds nothing."""
    config = load_verify_config()
    feats = ArmFeatures(config)
    rows = []
    bias = np.array([3.0, -2.0, 1.0, 0.1, 0.1, 0.1])
    for k in range(200):  # 200 Hz, every sample twice: a 100 Hz sensor republished
        t = k / 200.0
        w = bias + np.array([5.0 if (k // 2) * 2 >= 100 else 0.0, 0, 0, 0, 0, 0])
        rows.extend(feats.push(t, w))
    jump = np.array([r[kind_columns("jump", 1)] for _, r in rows])
    times = np.array([g for g, _ in rows])
    step = int(np.flatnonzero(times >= 0.5)[0])  # the tick holding the step's first sample
    assert jump[step, 0] == pytest.approx(5.0)
    quiet = 1e-12  # a mean of equal samples differs from them by rounding only
    assert np.all(jump[:step] < quiet) and np.all(jump[:, 1:] < quiet)
    assert np.all(jump[step + 3 :] < quiet)  # JUMP_STEPS later the reference holds the new level


@pytest.fixture(scope="module")
def nominal(cell: SimConfig) -> list[TrialFeatures]:
    """The verifier features of ten successes of the cell."""
    config = load_verify_config()
    return [trial_features(simulate_trial(cell, 100 + i), config) for i in range(10)]


def _alarms(
    successes: list[TrialFeatures], trial: Trial, signal: str
) -> tuple[Detection, Detection]:
    """The trial through a detector with `signal` beside wrench and timing, and without it."""
    config = load_verify_config()
    tf = trial_features(trial, config)
    with_it = Detector.fit(successes, config, ("wrench", signal, "timing")).run(tf)
    return with_it, Detector.fit(successes, config, ("wrench", "timing")).run(tf)


def test_the_transient_signal_alarms_at_a_push_the_change_sees_later(
    cell: SimConfig, nominal: list[TrialFeatures]
) -> None:
    """Trained on successes of the cell, the detector alarms within 0.1 s of a collision's
    push through the transient signal; without it, the same push is seen much later or never."""
    struck = simulate_trial(cell, 12, failure="collision")  # a 5 N push during insertion
    onset = label_of(struck).onset
    assert onset is not None
    with_jumps, without = _alarms(nominal, struck, "transient")
    assert with_jumps.alarm is not None and with_jumps.alarm_signal == "transient"
    assert onset <= with_jumps.alarm <= onset + 0.1
    assert without.alarm is None or without.alarm > with_jumps.alarm + 0.5


def test_the_departure_signal_alarms_on_a_slow_slip_the_change_sees_later(
    cell: SimConfig, nominal: list[TrialFeatures]
) -> None:
    """A slip that grows over 3.4 s during insertion: the departure from the sub-task's own
    level raises the alarm about a second after the slip starts; the change over lag_s alone
    sees it seconds later."""
    slipped = simulate_trial(cell, 28, failure="slip")
    onset = label_of(slipped).onset
    assert onset is not None and slipped.metadata["failure"]["duration_s"] > 3.0
    seen, without = _alarms(nominal, slipped, "departure")
    assert seen.alarm is not None and seen.alarm_signal == "departure"
    assert onset <= seen.alarm <= onset + 1.5
    assert without.alarm is None or without.alarm > seen.alarm + 1.0


def test_the_peg_task_is_struck_the_same_way(tmp_path: Path) -> None:
    from rcbht_introspection.sim.peg_config import load_peg_config
    from rcbht_introspection.sim.peg_simulate import simulate_peg_trial

    text = config_path("sim/peg.yaml").read_text().replace("[hole_yaw]", "[collision]")
    path = tmp_path / "peg.yaml"
    path.write_text(text)
    trial = simulate_peg_trial(load_peg_config(path), 2, failure="collision")
    record = trial.metadata["failure"]
    assert trial.outcome == "collision" and record["phase"] in ("reach", "search", "insert")
    label = label_of(trial)
    assert label.failure_class == "collision" and label.onset == pytest.approx(record["onset"])

"""Simulated failure labels: the deviation classes, the cycle of `--failures`, the onset rules
(first contact the nominal twin does not have, or the twin has and the trial lacks; else the
stroke's end), determinism, and the failure record in meta.json, sim_meta.json and a bag's
trial info."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.bags import read_trial_bag
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.sim import SimConfig, load_sim_config, simulate_trial, write_dataset
from rcbht_introspection.sim.contacts import feature_name
from rcbht_introspection.sim.dataset import trial_plan
from rcbht_introspection.sim.failures import deviation_signs, failure_classes
from rcbht_introspection.sim.onset import (
    CONTACT_CHECK,
    MISSING_CONTACT,
    NO_ONSET,
    NOVEL_CONTACT,
    STROKE_END,
    ContactLog,
    Onset,
    TwinWatch,
    contact_onset,
)
from rcbht_introspection.sim.simulate import draw_trial, failure_onset, run_physics

DEVIATION_SEED = 7
DEVIATION_CLASS = "deviation_x-y-"


@pytest.fixture(scope="module")
def config() -> SimConfig:
    return load_sim_config()


@pytest.fixture(scope="module")
def deviated(config: SimConfig) -> Trial:
    return simulate_trial(config, DEVIATION_SEED, failure=DEVIATION_CLASS)


def test_the_cycle_covers_every_class_once_per_two_rounds(config: SimConfig) -> None:
    classes = failure_classes(config.failures)
    dirs = config.failures.deviation_classes
    assert classes == (
        "misalignment",
        "jamming",
        "missed_snap",
        *(f"deviation_{d}" for d in dirs),
    )
    assert 6 <= len(dirs) <= 10
    plan = trial_plan(2 * len(classes), 3, True, classes)
    failures = [f for _, f in plan if f is not None]
    assert sorted(failures) == sorted(classes)  # every class exactly once
    assert [f for _, f in plan[::2]] == [None] * len(classes)


def test_deviation_class_names() -> None:
    assert deviation_signs("x+") == {"x": 1}
    assert deviation_signs("x-y+r-") == {"x": -1, "y": 1, "r": -1}
    for bad in ("", "y+x+", "x", "x+x-", "z+"):
        with pytest.raises(InputError, match="bad deviation class"):
            deviation_signs(bad)


def test_a_bad_deviation_class_in_the_config_names_file_line_and_field(tmp_path: Path) -> None:
    path = tmp_path / "sim.yaml"
    path.write_text("failures:\n  deviation_classes: [x+, q-]\n")
    with pytest.raises(InputError) as info:
        load_sim_config(path)
    assert info.value.field == "failures.deviation_classes[1]" and info.value.line == 2
    assert str(path) in str(info.value)


def test_second_deviation_family_overrides_only_the_sizes(config: SimConfig) -> None:
    root = Path(__file__).resolve().parents[1]
    other = load_sim_config(root / "config" / "sim/deviation_b.yaml")
    assert other.failures.deviation_classes == config.failures.deviation_classes
    assert other.geometry == config.geometry and other.controller == config.controller
    a, b = config.failures, other.failures
    assert (a.deviation_xy, a.deviation_yaw) != (b.deviation_xy, b.deviation_yaw)


def test_the_cell_repeats_one_program_against_a_fixtured_housing(config: SimConfig) -> None:
    """config/sim/cell.yaml: every drawn controller value is a constant, the housing's pose
    error is below the default's, the rest is the default; its deviation_a and deviation_b twins
    differ from it in the deviation sizes only: the lower and the upper part of its own."""
    root = Path(__file__).resolve().parents[1] / "config"
    cell = load_sim_config(root / "sim/cell.yaml")
    ranges = [
        v for v in dataclasses.asdict(cell.controller).values() if isinstance(v, tuple | list)
    ]
    assert len(ranges) >= 8 and all(lo == hi for lo, hi in ranges)
    assert cell.controller != config.controller
    v, d = cell.variation, config.variation
    assert v.offset_xy < d.offset_xy and v.offset_z < d.offset_z and v.offset_yaw < d.offset_yaw
    assert v == dataclasses.replace(
        d, offset_xy=v.offset_xy, offset_z=v.offset_z, offset_yaw=v.offset_yaw
    )
    assert (cell.geometry, cell.physics, cell.failures, cell.sensor) == (
        config.geometry,
        config.physics,
        config.failures,
        config.sensor,
    )
    low = load_sim_config(root / "sim/cell_deviation_a.yaml")
    high = load_sim_config(root / "sim/cell_deviation_b.yaml")
    f = cell.failures
    sizes = {"deviation_xy": f.deviation_xy, "deviation_yaw": f.deviation_yaw}
    for part in (low, high):
        assert dataclasses.replace(part, failures=cell.failures) == cell
        assert dataclasses.replace(part.failures, **sizes) == f
    # the two parts split the cell's deviation sizes where one ends and the other starts
    for key in sizes:
        (a0, a1), (b0, b1), (c0, c1) = (
            sizes[key],
            getattr(low.failures, key),
            getattr(high.failures, key),
        )
        assert a0 == b0 < b1 == c0 < c1 == a1, key


def test_a_deviation_trial_carries_class_onset_and_signed_offsets(
    config: SimConfig, deviated: Trial
) -> None:
    assert deviated.outcome == DEVIATION_CLASS and deviated.metadata["latched"] is False
    record = deviated.metadata["failure"]
    assert isinstance(record, dict)
    assert record["class"] == DEVIATION_CLASS
    assert record["onset_rule"] in (NOVEL_CONTACT, MISSING_CONTACT)
    offsets = record["deviation"]
    lo, hi = config.failures.deviation_xy
    assert -hi <= offsets["x"] <= -lo and -hi <= offsets["y"] <= -lo and offsets["yaw"] == 0.0
    onset = record["onset"]
    period = 1.0 / deviated.metadata["rate_hz"]
    assert onset == pytest.approx(round(onset / period) * period, abs=1e-9)  # on the sample grid
    assert 0.0 < onset < deviated.end_time
    # same seed, same label
    again = simulate_trial(config, DEVIATION_SEED, failure=DEVIATION_CLASS)
    assert again.metadata["failure"] == record
    np.testing.assert_array_equal(again.wrench["R"], deviated.wrench["R"])


def test_the_onset_is_a_contact_of_the_failure_trial(config: SimConfig, deviated: Trial) -> None:
    """Rerun the accepted draw's physics: a novel contact lies at or after its first contact
    and the part touches the named feature at the onset; a missing one it does not touch."""
    attempt = int(deviated.metadata["attempts"]) - 1  # type: ignore[call-overload]
    draw = draw_trial(config, np.random.default_rng([DEVIATION_SEED, attempt]), DEVIATION_CLASS)
    log = ContactLog(config)
    run_physics(config, draw.physics, draw.plan, False, observer=log)
    touching = [i for i, f in enumerate(log.features) if f]
    first_contact = (touching[0] + 1) * 0.005
    record = deviated.metadata["failure"]
    assert isinstance(record, dict)
    at_onset = {feature_name(f) for f in log.features[round(record["onset"] / 0.005) - 1]}
    if record["onset_rule"] == NOVEL_CONTACT:  # the trial touches what its twin does not
        assert record["onset"] >= first_contact - 0.005
        assert record["onset_contact"] in at_onset
    else:  # the twin touches what the trial does not
        assert record["onset_rule"] == MISSING_CONTACT
        assert record["onset_contact"] not in at_onset


def test_missed_snap_onset_is_the_landing_its_twin_makes_and_successes_have_none(
    config: SimConfig,
) -> None:
    """The housing sits lower than believed: the nominal twin lands while the trial's part is
    still in the air, so the onset is a missing contact, before the trial's approach ends."""
    missed = simulate_trial(config, 5, failure="missed_snap")
    record = missed.metadata["failure"]
    assert isinstance(record, dict) and record["onset_rule"] == MISSING_CONTACT
    assert 0.0 < record["onset"] < missed.state_times[1], (record, missed.state_times)
    assert record["onset_contact"] and record["deviation"] is None
    success = simulate_trial(config, 5)
    assert success.outcome == "success" and "failure" not in success.metadata


def test_contacts_that_never_differ_fall_back_to_the_stroke_end(config: SimConfig) -> None:
    """A trial watched against its own physics never diverges: a missed snap's onset is then
    where its planned stroke ended with the part not seated; a trial that seated has none."""
    missed = draw_trial(config, np.random.default_rng([5, 0]), "missed_snap")
    log = ContactLog(config)
    result = run_physics(config, missed.physics, missed.plan, False, observer=log)
    same = dataclasses.replace(missed, twin=missed.physics)
    onset = failure_onset(config, same, False, result.state, log)
    assert result.state.stroke_time is not None and result.state.seat_time is None
    assert onset == Onset(result.state.stroke_time, STROKE_END)
    nominal = draw_trial(config, np.random.default_rng([5, 0]), None)
    log = ContactLog(config)
    result = run_physics(config, nominal.physics, nominal.plan, False, observer=log)
    assert result.state.seat_time is not None
    assert failure_onset(config, nominal, False, result.state, log) == Onset(None, NO_ONSET)


def test_contacts_after_the_twin_ended_are_novel(config: SimConfig) -> None:
    """A failure trial that goes on after its twin ended differs at its next contact."""
    log = ContactLog(config, features=[frozenset(), frozenset(), frozenset({("floor", -1)})])
    watch = TwinWatch(config, log)
    onset = contact_onset(lambda: None, watch)  # a twin that ends before its first check
    assert onset == Onset(3 * CONTACT_CHECK, NOVEL_CONTACT, feature_name(("floor", -1)))
    assert contact_onset(lambda: None, TwinWatch(config, ContactLog(config))) is None


def test_failure_record_in_bags_and_sim_meta(tmp_path: Path) -> None:
    paths = write_dataset(tmp_path, 2, seed=4, failures=True, fmt="bag")
    index = json.loads((tmp_path / "sim_meta.json").read_text())["trials"]
    assert "failure" not in index[0]
    record = index[1]["failure"]
    assert record["class"] == "misalignment" == index[1]["outcome"]
    assert record["onset_rule"] == NOVEL_CONTACT
    # the part's offset against the housing: the housing's own (4-7 mm in y) negated
    offset, housing_y = record["deviation"], index[1]["female_offset"][1]
    assert offset["x"] == 0.0 and offset["yaw"] == 0.0
    assert 0.004 <= abs(offset["y"]) <= 0.0075 and offset["y"] * housing_y < 0
    back = read_trial_bag(paths[1])
    assert back.outcome == "misalignment" and back.metadata["failure"] == record
    assert "failure" not in read_trial_bag(paths[0]).metadata

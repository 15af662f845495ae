"""The reference planner without ROS: each policy's aborts and corrections from verdicts and
attempt results, and the recovery table's loader."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from rcbht_introspection.errors import InputError
from rcbht_introspection.plan.planner import (
    Decision,
    Planner,
    Report,
    Steps,
    make_planner,
    search_grid,
)
from rcbht_introspection.plan.recovery import (
    ClassRecovery,
    Correction,
    RecoveryConfig,
    load_recovery_config,
)

TABLE = RecoveryConfig(
    max_attempts=4,
    naming_wait_s=0.5,
    bounds={"x": 0.01, "y": 0.01, "z": 0.01, "yaw": 0.3},
    search_step={"x": 0.002, "y": 0.002, "yaw": 0.05},
    classes={
        "deviation": ClassRecovery("undo_direction", size={"x": 0.002, "yaw": 0.06}),
        "misalignment": ClassRecovery("try", candidates=({"y": 0.005}, {"y": -0.005})),
        "jamming": ClassRecovery("undo_direction", size={"yaw": 0.16}, candidates=({"yaw": 0.1},)),
        "anomaly": ClassRecovery("retry"),
    },
)
FAILED = Report(False, "timeout")


def _abort_on(
    planner: Planner,
    cls: str,
    directions: dict[str, str],
    probabilities: dict[str, float] | None = None,
    at: float = 5.0,
) -> None:
    """An alarm at `at` named `cls` until the planner aborts (naming_wait_s later)."""
    t = at
    while planner.verdict(t, True, cls, directions, probabilities) is None:
        t += 0.05
        assert t < at + 5.0, "the planner never aborted"


def test_none_stops_after_its_one_attempt() -> None:
    planner = Planner("none", TABLE)
    assert planner.first().correction == Correction()
    assert planner.verdict(5.0, True, "deviation_x+", {"x": "+"}) is None
    assert planner.ended(FAILED, 20.0).kind == "stop"


def test_retry_runs_the_same_plan_until_seated_or_out_of_attempts() -> None:
    planner = Planner("retry", TABLE)
    planner.first()
    kinds = [planner.ended(FAILED, 20.0) for _ in range(3)]
    assert [d.correction for d in kinds] == [Correction()] * 3
    assert planner.ended(FAILED, 20.0).kind == "stop"
    seated = Planner("retry", TABLE)
    seated.first()
    assert seated.ended(Report(True, "seated"), 27.0).reason == "seated"


def test_search_walks_its_grid_one_axis_first_within_the_bounds() -> None:
    grid = search_grid({"x": 0.002, "yaw": 0.05})
    first = [next(grid) for _ in range(8)]
    assert first[:4] == [
        Correction(x=0.002),
        Correction(x=-0.002),
        Correction(yaw=0.05),
        Correction(yaw=-0.05),
    ]
    assert first[4] == Correction(x=0.002, yaw=0.05)
    planner = Planner("search", TABLE)
    planner.first()
    assert planner.ended(FAILED, 20.0).correction == Correction(x=0.002)


def test_introspect_waits_for_a_class_then_undoes_the_named_direction() -> None:
    planner = Planner("introspect", TABLE, {"deviation_x+": Steps(size={"x": 0.0025})})
    planner.first()
    assert planner.verdict(5.0, True, "", {}) is None  # alarm, no class yet
    assert planner.verdict(5.3, True, "deviation_x+", {"x": "+", "y": "0"}) is None
    abort = planner.verdict(5.5, True, "deviation_x+", {"x": "+", "y": "0"})
    assert isinstance(abort, Decision) and abort.kind == "abort"
    assert abort.failure_class == "deviation_x+" and abort.reason == "x+"
    nxt = planner.ended(Report(False, "aborted"), 7.0)
    assert nxt.correction == Correction(x=-0.0025)  # the learnt size, not the table's


def test_introspect_does_not_abort_a_corrected_attempt_and_halves_an_overshoot() -> None:
    planner = Planner("introspect", TABLE)
    planner.first()
    _abort_on(planner, "deviation_x+", {"x": "+"})
    planner.ended(Report(False, "aborted"), 6.0)
    for t in (5.0, 6.0, 7.0):  # the corrected attempt departs from nominal by design
        assert planner.verdict(t, True, "deviation_x-", {"x": "-"}) is None
    third = planner.ended(FAILED, 20.0)
    assert math.isclose(third.correction.x, -0.002 + 0.001)


def test_a_missed_correction_moves_by_the_learnt_spread_then_halves() -> None:
    """A class whose name carries its side: an undershoot (the same direction named again)
    moves on by the learnt spread, an overshoot back by half the last step; only the class's
    own axes move, by the steps learnt for it."""
    trained_on = {
        "deviation_by_class": {"deviation_x+": {"size": {"x": 0.002}, "spread": {"x": 0.0005}}}
    }
    planner = make_planner("introspect", TABLE, trained_on)
    planner.first()
    _abort_on(planner, "deviation_x+", {"x": "+", "r": "-"})
    assert planner.ended(Report(False, "aborted"), 6.0).correction == Correction(x=-0.002)
    planner.verdict(5.0, True, "deviation_x+", {"x": "+"})  # still short of the slip
    third = planner.ended(FAILED, 20.0).correction
    assert math.isclose(third.x, -0.0025) and third.yaw == 0.0
    planner.verdict(5.0, True, "deviation_x-", {"x": "-"})  # now beyond it
    assert math.isclose(planner.ended(FAILED, 20.0).correction.x, -0.0025 + 0.00025)


def test_a_side_the_verdict_guessed_is_mirrored_before_it_is_refined() -> None:
    """A class whose side comes from the verdict (jamming turns either way): named again after
    its correction failed, whichever way, the other side at the same size comes next, once;
    then the spread as for any class."""
    trained_on = {"deviation_by_class": {"jamming": {"size": {"r": 0.16}, "spread": {"r": 0.03}}}}
    planner = make_planner("introspect", TABLE, trained_on)
    planner.first()
    _abort_on(planner, "jamming", {"x": "+", "r": "-"})
    assert planner.ended(Report(False, "aborted"), 6.0).correction == Correction(yaw=0.16)
    planner.verdict(5.0, True, "jamming", {"r": "+"})  # flipped: overshoot, or the wrong side
    assert planner.ended(FAILED, 20.0).correction == Correction(yaw=-0.16)
    planner.verdict(5.0, True, "jamming", {"r": "+"})  # short on the other side
    assert math.isclose(planner.ended(FAILED, 20.0).correction.yaw, -0.19)
    assert planner.ended(FAILED, 20.0).kind == "stop"  # TABLE's four attempts are spent


def test_a_refinement_yields_to_a_runner_up_worth_more_than_half_the_hypothesis() -> None:
    """Correcting along a wrong hypothesis makes an error of its own family: named again, it
    is refined only while its probability is worth twice the runner-up's."""

    def third(ranked: dict[str, float]) -> Correction:
        planner = Planner("introspect", TABLE)
        planner.first()
        _abort_on(planner, "jamming", {"r": "-"}, ranked)
        assert planner.ended(Report(False, "aborted"), 6.0).correction == Correction(yaw=0.16)
        planner.verdict(5.0, True, "jamming", {"r": "+"})
        return planner.ended(FAILED, 20.0).correction

    assert third({"jamming": 0.8, "deviation_x+": 0.2}) == Correction(yaw=-0.16)  # other side
    assert third({"jamming": 0.5, "deviation_x+": 0.4}) == Correction(x=-0.002)


def test_a_class_named_without_directions_falls_back_to_its_candidates() -> None:
    planner = Planner("introspect", TABLE)
    planner.first()
    _abort_on(planner, "jamming", {"r": "0"})
    assert planner.ended(Report(False, "aborted"), 6.0).correction == Correction(yaw=0.1)


def test_a_contradicted_diagnosis_gives_way_to_the_next_likeliest_class() -> None:
    planner = Planner("introspect", TABLE)
    planner.first()
    ranked = {"misalignment": 0.6, "deviation_r+": 0.3, "jamming": 0.1}
    _abort_on(planner, "misalignment", {}, ranked)
    assert planner.ended(Report(False, "aborted"), 6.0).correction == Correction(y=0.005)
    planner.verdict(5.0, True, "deviation_x-", {"x": "-"})  # another family named
    third = planner.ended(FAILED, 20.0)
    assert third.correction == Correction(yaw=-0.06)  # the runner-up, from the clean plan


def test_a_try_class_named_again_tries_its_next_candidate_when_that_is_worth_more() -> None:
    def third(ranked: dict[str, float]) -> Correction:
        planner = Planner("introspect", TABLE)
        planner.first()
        _abort_on(planner, "misalignment", {}, ranked)
        planner.ended(Report(False, "aborted"), 6.0)
        planner.verdict(5.0, True, "misalignment", {})
        return planner.ended(FAILED, 20.0).correction

    assert third({"misalignment": 0.9, "deviation_r+": 0.1}) == Correction(y=-0.005)
    assert third({"misalignment": 0.5, "deviation_r+": 0.4}) == Correction(yaw=-0.06)


def test_an_unnamed_alarm_aborts_after_the_wait_and_retries_as_before() -> None:
    planner = Planner("introspect", TABLE)
    planner.first()
    assert planner.verdict(5.0, True, "", {}) is None
    abort = planner.verdict(5.5, True, "", {})
    assert abort is not None and abort.failure_class == "anomaly"
    assert planner.ended(Report(False, "aborted"), 6.0).correction == Correction()


def test_the_oracle_aborts_at_the_first_alarm_then_applies_the_truth() -> None:
    truth = Correction(x=-0.002, yaw=0.01)
    planner = Planner("oracle", TABLE, truth=truth)
    planner.first()
    assert planner.verdict(4.0, False, "", {}) is None
    assert planner.verdict(5.0, True, "", {}) is not None
    assert planner.ended(Report(False, "aborted"), 6.0).correction == truth
    assert planner.verdict(5.0, True, "jamming", {}) is None


def test_corrections_stay_within_the_bounds_and_bad_ones_are_named() -> None:
    planner = Planner("introspect", TABLE, {"deviation_x+": Steps(size={"x": 0.05})})
    planner.first()
    _abort_on(planner, "deviation_x+", {"x": "+"})
    assert planner.ended(Report(False, "aborted"), 6.0).correction.x == -0.01
    bounds = TABLE.bounds
    assert Correction(x=0.005).problem(bounds) is None
    assert "not finite" in (Correction(y=math.nan).problem(bounds) or "")
    assert "beyond its bound" in (Correction(yaw=0.5).problem(bounds) or "")


def test_the_shipped_table_loads_and_a_bad_axis_names_file_line_and_field(
    tmp_path: Path,
) -> None:
    table = load_recovery_config("snap")
    assert table.recovery_of("deviation_x+y-").action == "undo_direction"
    assert table.recovery_of("unheard_of").action == "retry"
    bad = tmp_path / "recovery.yaml"
    bad.write_text("max_attempts: 3\nbounds: {x: 0.01, w: 0.2}\n")
    with pytest.raises(InputError, match=r"recovery.yaml.*line 2.*bounds"):
        load_recovery_config(path=bad)

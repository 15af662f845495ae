"""`rcbht audit` (audit/, commands/audit.py): data sets built here whose labels change convention
at a known trial or do not, a frozen sensor, a jump of the free-motion level between sessions,
lost samples and an outlying trial; the permutation test's calibration under the null; the CLI,
its JSON and figure, bad input; and the REAL HIRO convention change (shared data)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from rcbht_introspection.audit import (
    AuditReport,
    AuditSettings,
    audit_paths,
    audit_trials,
    report_dict,
)
from rcbht_introspection.audit.changepoint import find_changes, permutation_p
from rcbht_introspection.audit.findings import span
from rcbht_introspection.cli import main
from rcbht_introspection.io.hiro import write_trial
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.task import Task

TASK = Task(("reach", "grasp", "lift", "place"))
RATE = 100.0
MOTIONS = (1.5, 2.0, 1.0, 1.5)
"""Seconds of the four motions a synthetic trial performs, in order."""
MOTION_WRENCH = np.array(
    [[0.0, 0.0, 0.5, 0, 0, 0], [3.0, 0.0, -4.0, 0, 0.2, 0], [0.0, 2.0, -8.0, 0.1, 0, 0],
     [-1.0, 0.0, 1.0, 0, 0, 0.1]]
)  # fmt: skip
"""Mean wrench of each motion: what a classifier of the windows can tell them by."""
FAST = AuditSettings(permutations=1999)


def synthetic_trial(
    name: str,
    rng: np.random.Generator,
    moved: float | None = None,
    level: tuple[float, ...] = (0.0,) * 6,
) -> Trial:
    """A trial of the four motions (lengths jittered by 3 %) labelled reach, grasp, lift, place at
    their starts; `moved`: lift starts that many seconds into grasp's motion instead (the
    grasp|lift boundary of another labelling convention)."""
    lengths = np.asarray(MOTIONS) * np.exp(rng.normal(0.0, 0.03, len(MOTIONS)))
    starts = np.concatenate(([0.0], np.cumsum(lengths)[:-1]))
    time = np.arange(0.0, float(lengths.sum()), 1.0 / RATE)
    motion = np.searchsorted(starts, time, side="right") - 1
    wrench = MOTION_WRENCH[motion] + np.asarray(level) + rng.normal(0.0, 0.05, (len(time), 6))
    state = [float(t) for t in starts]
    if moved is not None:
        state[2] = state[1] + moved
    state = [round(t * RATE) / RATE for t in state]  # on a sample, as a state machine's event
    return Trial(name, time, {"R": wrench}, tuple(state), phases=TASK.subtasks)


def trial_set(n: int = 24, seed: int = 0, moved_from: int | None = None) -> list[Trial]:
    """n trials named trial-01...; from trial index `moved_from` on, lift starts 0.3 s into
    grasp's motion (a convention change between trial-<moved_from> and the next)."""
    rng = np.random.default_rng(seed)
    return [
        synthetic_trial(
            f"trial-{i + 1:02d}", rng, 0.3 if moved_from is not None and i >= moved_from else None
        )
        for i in range(n)
    ]


def kinds(report: AuditReport) -> list[str]:
    return [f["kind"] for f in report_dict(report)["findings"]]


def test_a_convention_change_is_named_at_its_trial_with_its_two_subtasks() -> None:
    report = audit_trials(trial_set(moved_from=12), FAST, TASK)
    found = report.of_kind("convention_change")
    assert len(found) == 1
    change = found[0]
    assert change.subtasks == ("grasp", "lift")
    assert change.between == ("trial-12", "trial-13")
    grasp, lift = change.strength["grasp"], change.strength["lift"]
    assert grasp["p_bonferroni"] <= 0.01 and lift["p_bonferroni"] <= 0.01
    assert grasp["shift_sigmas"] < 0 < lift["shift_sigmas"]
    assert lift["median_before_s"] == pytest.approx(1.0, rel=0.1)
    assert lift["median_after_s"] == pytest.approx(2.7, rel=0.1)
    # the same motion is called grasp before and lift after: each side's model says so
    called = change.detail["classifier"]["after_called_by_model_before"]["lift"]
    assert next(iter(called)) == "grasp"
    assert "'grasp'" in change.evidence
    assert change.action.startswith("relabel")
    assert "duration_shift" not in kinds(report)


def test_a_set_without_a_change_reports_none() -> None:
    for seed in (0, 1, 2):
        report = audit_trials(trial_set(seed=seed), FAST, TASK)
        assert report.of_kind("convention_change") == []
        assert report.of_kind("duration_shift") == []
        assert report.of_kind("session") == []
        assert report.of_kind("session_change") == []


def test_a_frozen_sensor_is_named_with_its_trial_and_length() -> None:
    trials = trial_set(n=8)
    frozen = trials[3]
    wrench = frozen.wrench["R"].copy()
    wrench[100:250] = wrench[100]  # 1.5 s of one value
    trials[3] = Trial(frozen.name, frozen.time, {"R": wrench}, frozen.state_times,
                      phases=frozen.phases)  # fmt: skip
    found = audit_trials(trials, FAST, TASK).of_kind("frozen_sensor")
    assert len(found) == 1
    assert found[0].trials == ("trial-04",)
    assert found[0].strength["samples"] == 150
    assert found[0].strength["longest_s"] == pytest.approx(1.49)


def test_a_session_at_another_level_is_found_whatever_the_order() -> None:
    """Nine trials 2 N higher in Fz, among eleven: one session finding naming exactly them,
    with their level, the same when the trials come interleaved or reversed."""
    rng = np.random.default_rng(5)
    trials = [
        synthetic_trial(f"trial-{i + 1:02d}", rng, level=(0, 0, 2.0 if i >= 11 else 0.0, 0, 0, 0))
        for i in range(20)
    ]
    high = tuple(f"trial-{i + 1:02d}" for i in range(11, 20))
    for order in (trials, trials[::-1], trials[1::2] + trials[::2]):
        report = audit_trials(order, FAST, TASK)
        found = report.of_kind("session")
        assert len(found) == 1
        assert sorted(found[0].trials) == list(high)
        top = found[0].detail["channels"][0]
        assert top["channel"] == "R.Fz"
        assert top["level"] - top["reference"] == pytest.approx(2.0, abs=0.1)
        assert report.of_kind("convention_change") == []
        sessions = report_dict(report)["sessions"]["sessions"]
        assert [s["count"] for s in sessions] == [11, 9]


def test_a_small_level_shift_in_input_order_is_a_change_within_the_session() -> None:
    """Fz 0.05 N higher from the tenth trial on (five standard errors of a level): no group of
    its own, but a change in input order, found where it is."""
    rng = np.random.default_rng(5)
    trials = [
        synthetic_trial(f"trial-{i + 1:02d}", rng, level=(0, 0, 0.05 if i >= 9 else 0.0, 0, 0, 0))
        for i in range(20)
    ]
    report = audit_trials(trials, FAST, TASK)
    assert report.of_kind("session") == []
    found = report.of_kind("session_change")
    assert len(found) == 1 and found[0].between == ("trial-09", "trial-10")
    top = found[0].detail["channels"][0]
    assert top["channel"] == "R.Fz"
    assert top["after"] - top["before"] == pytest.approx(0.05, abs=0.01)
    assert report_dict(report)["sessions"]["changes"][0]["between"] == ["trial-09", "trial-10"]


def test_sessions_split_at_a_gap_far_beyond_the_spread_only() -> None:
    """Levels spread evenly over 1 N are one session; the same with two clusters 10 N apart
    (half and half) are two, each named by its own members."""
    from rcbht_introspection.audit.sessions import channel_groups

    even = np.random.default_rng(1).uniform(0.0, 1.0, 30)
    assert len(channel_groups(even, 0.01)) == 1
    two = np.concatenate([even[:15], even[15:] + 10.0])
    assert sorted(sorted(g) for g in channel_groups(two, 0.01)) == [
        list(range(15)),
        list(range(15, 30)),
    ]


def test_a_small_difference_of_a_scripted_duration_is_no_outlier() -> None:
    """Durations that do not vary (a scripted robot: one trial repeated): grasp 0.2 s longer in
    one is dozens of robust sigmas out, but neither half a second nor a quarter of the sub-task:
    no finding; 0.6 s longer (30 %, and lift 0.6 s shorter: 60 %) is one of each."""
    base = trial_set(n=1, seed=3)[0]

    def copy(i: int, later: float = 0.0) -> Trial:
        s = base.state_times
        state = (s[0], s[1], round((s[2] + later) * RATE) / RATE, s[3])
        return Trial(f"trial-{i + 1:02d}", base.time, base.wrench, state, phases=base.phases)

    moved = [(("grasp",), ("trial-06",)), (("lift",), ("trial-06",))]
    for later, found in ((0.2, []), (0.6, moved)):
        trials = [copy(i, later if i == 5 else 0.0) for i in range(16)]
        outliers = audit_trials(trials, FAST, TASK).of_kind("duration_outlier")
        assert [(f.subtasks, f.trials) for f in outliers] == found
        if not found:
            assert audit_trials(trials, FAST, TASK).durations[1].parts[0].sigma_log < 0.02


def test_lost_samples_and_an_outlying_duration_are_named() -> None:
    trials = trial_set(n=16, seed=3)
    lossy = trials[5]
    keep = np.ones(len(lossy.time), dtype=bool)
    keep[300:320] = False  # 0.2 s lost in the middle of grasp
    trials[5] = Trial(lossy.name, lossy.time[keep], {"R": lossy.wrench["R"][keep]},
                      lossy.state_times, phases=lossy.phases)  # fmt: skip
    slow = trials[9]
    state = slow.state_times
    long_wrench = np.vstack([slow.wrench["R"], np.repeat(slow.wrench["R"][-1:], 300, 0)])
    long_wrench[len(slow.time) :] += np.random.default_rng(9).normal(0, 0.05, (300, 6))
    long_time = np.arange(len(long_wrench)) / RATE  # place takes 3 s longer
    trials[9] = Trial(slow.name, long_time, {"R": long_wrench}, state, phases=slow.phases)
    report = audit_trials(trials, FAST, TASK)
    gaps = report.of_kind("gaps")
    assert len(gaps) == 1 and gaps[0].trials == ("trial-06",)
    assert gaps[0].strength["longest_s"] == pytest.approx(0.21)
    outliers = report.of_kind("duration_outlier")
    assert [(f.subtasks, f.trials) for f in outliers] == [(("place",), ("trial-10",))]


def test_the_changepoint_test_holds_its_level_under_the_null() -> None:
    """Exchangeable values (no change): p <= 0.1 in about 10 % of the sequences, ties or not."""
    rng = np.random.default_rng(11)
    for draw in (lambda: rng.normal(size=20), lambda: rng.integers(0, 3, 20).astype(float)):
        p = [permutation_p(draw(), 199, rng)[1] for _ in range(300)]
        assert 0.05 <= np.mean(np.asarray(p) <= 0.1) <= 0.16


def test_binary_segmentation_finds_two_steps() -> None:
    steps = np.r_[np.zeros(15), np.full(15, 3.0), np.full(15, 6.0)]
    x = steps + np.random.default_rng(2).normal(0, 0.3, 45)
    changes = find_changes(x, 0.01, 999, 0).changes
    assert [c.split for c in changes] == [15, 30]
    assert all(c.p_adjusted <= 0.01 for c in changes)


def test_span_shortens_the_last_name() -> None:
    assert span(["20121127-HIROSA-S-01", "20121127-HIROSA-S-21"]) == "20121127-HIROSA-S-01..21"
    assert span(["s01", "s15"]) == "s01..s15"
    assert span(["a"]) == "a"


def write_set(root: Path, trials: list[Trial]) -> Path:
    for trial in trials:
        write_trial(trial, root / trial.name, TASK)
    return root


def test_cli_prints_the_change_and_writes_json_and_figure(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = write_set(tmp_path / "set", trial_set(n=16, moved_from=8))
    out, fig = tmp_path / "audit.json", tmp_path / "audit.png"
    code = main(["audit", str(data), "--json", str(out), "--plot", str(fig),
                 "--permutations", "999"])  # fmt: skip
    assert code == 0
    text = capsys.readouterr().out
    assert "convention changes: 1 (grasp|lift between trial-08 and trial-09)" in text
    assert "do: relabel" in text
    report = json.loads(out.read_text())
    assert report["format"] == "rcbht-audit" and report["format_version"] == 1
    assert report["summary"]["convention_change"] == 1
    assert report["task"]["subtasks"] == list(TASK.subtasks)
    assert [t["name"] for t in report["trials"]][:2] == ["trial-01", "trial-02"]
    assert set(report["durations"]) == set(TASK.subtasks)
    finding = report["findings"][0]
    assert {"kind", "message", "trials", "subtasks", "between", "strength", "action"} <= set(
        finding
    )
    assert fig.stat().st_size > 10_000


def test_trial_bags_are_audited_like_trial_folders(tmp_path: Path) -> None:
    from rcbht_introspection.io.bags import write_trial_bag

    trials = trial_set(n=16, moved_from=8)
    for trial in trials:
        write_trial_bag(trial, tmp_path / f"{trial.name}.mcap")
    bags = audit_paths([tmp_path], FAST)
    folders = audit_paths([write_set(tmp_path / "set", trials)], FAST)
    assert [f.name for f in bags.facts] == [t.name for t in trials]
    assert bags.task.subtasks == TASK.subtasks
    for report in (bags, folders):
        (change,) = report.of_kind("convention_change")
        assert change.between == ("trial-08", "trial-09")
    assert bags.facts[0].durations == pytest.approx(folders.facts[0].durations, abs=1e-6)


def test_bad_input_is_counted_and_nothing_readable_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = write_set(tmp_path / "set", trial_set(n=6))
    (data / "trial-03" / "R_State.dat").write_text("0\nabc\n")
    report = audit_paths([data], FAST)
    bad = report.of_kind("unreadable")
    assert len(bad) == 1 and bad[0].trials[0].endswith("trial-03")
    assert "line 2" in bad[0].message and "state time" in bad[0].message
    assert len(report.facts) == 5
    (tmp_path / "bad" / "x").mkdir(parents=True)
    (tmp_path / "bad" / "x" / "R_Torques.dat").write_text("0 1 2 3\n")
    assert main(["audit", str(tmp_path / "bad")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "R_Torques.dat" in err[0]
    assert main(["audit", str(data), "--alpha", "2"]) == 2
    assert "field --alpha" in capsys.readouterr().err


def test_state_times_after_the_data_are_counted_where_they_are(tmp_path: Path) -> None:
    data = write_set(tmp_path / "set", trial_set(n=6))
    state = data / "trial-02" / "R_State.dat"
    state.write_text(state.read_text() + "99.0\n")  # after the last sample
    report = audit_paths([data], FAST)
    found = report.of_kind("dropped_state_times")
    assert len(found) == 1 and found[0].trials == ("trial-02",)
    assert found[0].detail["trials"]["trial-02"] == [
        {"line": 5, "time": 99.0, "reason": "after the data"}
    ]


@pytest.mark.shared_data
def test_real_hiro_convention_change_and_none_on_sim(hiro_data: Path) -> None:
    """REAL: S-01..21 give rotation 8.3 s and insertion 0.94 s, S-22..46 rotation 5 ms and
    insertion 6.7 s; the simulated set keeps one convention."""
    report = audit_paths([hiro_data / "REAL_HIRO_ONE_SA_SUCCESS"], FAST)
    found = report.of_kind("convention_change")
    assert len(found) == 1
    assert found[0].subtasks == ("rotation", "insertion")
    assert found[0].between == ("20121127-HIROSA-S-21", "20121127-HIROSA-S-22")
    rotation, insertion = found[0].strength["rotation"], found[0].strength["insertion"]
    assert rotation["median_before_s"] == pytest.approx(8.31, abs=0.01)
    assert rotation["median_after_s"] == pytest.approx(0.005)
    assert insertion["median_before_s"] == pytest.approx(0.94, abs=0.01)
    assert insertion["median_after_s"] == pytest.approx(6.67, abs=0.05)
    assert max(rotation["p_bonferroni"], insertion["p_bonferroni"]) <= 0.01
    sim = audit_paths([hiro_data / "SIM_HIRO_ONE_SA_SUCCESS"], FAST)
    assert sim.of_kind("convention_change") == []
    assert sim.of_kind("duration_shift") == []


@pytest.fixture(scope="module")
def baxter_session_a(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """The 15 real Baxter bags of session_a imported as trial bags (one command line)."""
    from conftest import HIRO, require

    bags = sorted((HIRO.parent / "baxter_pick_and_place" / "session_a").glob("*.bag"))
    require(len(bags) == 15, "Baxter session_a bags not found")
    out = tmp_path_factory.mktemp("baxter")
    assert main(["bag", "import", *map(str, bags), "--out", str(out), "--wrench",
                 "/tag_multimodal.wrench_stamped", "--phase", "/tag_multimodal.tag",
                 "--phase-map", "0=-,1=approach,2=grasp,5=lift,3=transport,4=place"]) == 0  # fmt: skip
    return sorted(out.glob("s??.mcap"))


@pytest.mark.shared_data
def test_baxter_session_a_has_one_session_and_no_duration_finding(
    baxter_session_a: list[Path],
) -> None:
    """The scripted robot's sub-task durations differ by 0.1-0.2 s of 4-9 s: no outlier."""
    report = audit_paths(baxter_session_a, AuditSettings(permutations=999))
    assert len(report.facts) == 15
    kinds = {f.kind for f in report.findings}
    assert not kinds & {"duration_outlier", "duration_shift", "convention_change", "session"}
    assert len(report.sessions.groups) == 1


@pytest.mark.shared_data
def test_baxter_copies_with_a_sensor_offset_are_one_session_in_any_order(
    baxter_session_a: list[Path], tmp_path: Path
) -> None:
    """Copies of three session_a bags with +18 N on Fz (another day's bias): one session finding
    naming exactly them and their level, whatever the order of the inputs."""
    from rcbht_introspection.io.bags import read_trial_bag, write_trial_bag

    copies = []
    for path in baxter_session_a[2:11:4]:  # s03, s07, s11
        trial = read_trial_bag(path)
        wrench = {arm: w.copy() for arm, w in trial.wrench.items()}
        wrench["R"][:, 2] += 18.0
        name = f"offset_{trial.name}"
        shifted = Trial(name, trial.time, wrench, trial.state_times, dict(trial.metadata),
                        phases=trial.phases)  # fmt: skip
        write_trial_bag(shifted, tmp_path / f"{name}.mcap")
        copies.append(tmp_path / f"{name}.mcap")
    names = sorted(p.stem for p in copies)
    inputs = [*baxter_session_a, *copies]
    orders = (
        inputs,
        inputs[::-1],
        [*copies[:1], *baxter_session_a[:7], *copies[1:], *baxter_session_a[7:]],
    )
    settings = AuditSettings(permutations=199, classifier=False)
    for order in orders:
        found = audit_paths(order, settings).of_kind("session")
        assert len(found) == 1
        assert sorted(found[0].trials) == names
        top = found[0].detail["channels"][0]
        assert top["channel"] == "R.Fz"
        assert top["level"] - top["reference"] == pytest.approx(18.0, abs=1.0)
        assert top["level"] > 18.0

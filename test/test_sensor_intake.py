"""Sensor intake without ROS: repeated stamps, a frozen sensor, tare and tool gravity, in the
segmenter session (live) and in the batch readers and commands, on generated data."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest

from rcbht_introspection.cli import main
from rcbht_introspection.errors import InputError
from rcbht_introspection.io.hiro import read_trial, write_trial
from rcbht_introspection.io.sensor_checks import (
    FrozenWatch,
    RepeatedPolicy,
    frozen_runs,
    resolve_repeated_stamps,
    trial_findings,
)
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.live.gravity import (
    compensate_gravity,
    gravity_wrench,
    rotation_from_quaternion,
)
from rcbht_introspection.live.health import OK, WARN, ArmHealth
from rcbht_introspection.live.intake import IntakeConfig, Tare, tare_recording
from rcbht_introspection.live.offline import offline_stream_words
from rcbht_introspection.live.segmenter import SegmenterSession, arm_stream_factory
from rcbht_introspection.taxonomy.words import Word

ORIGIN_NS = 1_700_000_000 * 10**9


def wrench_signal(n: int, dt: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(time s, wrench (n, 6)): piecewise-linear contacts plus sensor noise, never still."""
    rng = np.random.default_rng(seed)
    t = np.round(np.arange(n) * dt, 9)
    knots = np.linspace(0, t[-1], 12)
    base = np.column_stack([np.interp(t, knots, rng.normal(0, 5, 12)) for _ in range(6)])
    return t, base + rng.normal(0, 0.02, base.shape) + 3.0  # + a sensor bias


def jittered_stamps(n: int, seed: int) -> tuple[np.ndarray, int]:
    """Integer-ns stamps of a ~100 Hz sensor with 5.5-30 ms intervals, about one in eight of them
    repeating the previous stamp (the driver stamps a batch of readings at once)."""
    rng = np.random.default_rng(seed)
    steps = rng.uniform(5.5e6, 30e6, n).astype(np.int64)
    repeat = rng.random(n) < 0.125
    repeat[0] = False
    steps[repeat] = 0
    return ORIGIN_NS + np.cumsum(steps), int(repeat.sum())


def feed(
    session: SegmenterSession,
    stamps: np.ndarray,
    wrench: np.ndarray,
    events: Sequence[tuple[int, str]] = (),
) -> list[Word]:
    """Push every sample (arm R), each event after the last sample stamped at or before it, then
    the end event; the words in release order."""
    words: list[Word] = []
    pending = [*events, (int(stamps[-1]), "done")]
    for i, stamp in enumerate(stamps):
        out = session.push("R", int(stamp), wrench[i])
        words += [w for b in out.batches for w in b.words]
        following = int(stamps[i + 1]) if i + 1 < len(stamps) else None
        while pending and (following is None or pending[0][0] < following):
            out = session.phase(pending.pop(0)[1])
            words += [w for b in out.batches for w in b.words]
    return words


def offline_words(time: np.ndarray, wrench: np.ndarray, state: tuple[float, ...] = ()) -> list:
    """The words segmenter_node must give for these samples (taxonomy/stream fed in order)."""
    trial = Trial("t", time, {"R": wrench}, state_times=state)
    return offline_stream_words(trial, arm_stream_factory())["R"]


# --------------------------------------------------------------------------- frozen sensor


def test_frozen_runs_and_the_live_watch_agree() -> None:
    t, wrench = wrench_signal(3000, 0.01, seed=1)  # 100 Hz, 30 s
    wrench[1000:1400] = wrench[1000]  # 4 s frozen
    wrench[2000:2006] = wrench[2000]  # 6 equal samples (the longest run in the HIRO data)
    wrench[2500:2515] = wrench[2500]  # 15 samples, 0.14 s: too short for 0.5 s
    runs = frozen_runs(t, wrench, min_samples=20, min_s=0.5)
    assert [(r.start, r.stop) for r in runs] == [(1000, 1400)]
    assert runs[0].t1 - runs[0].t0 == pytest.approx(3.99)
    watch = FrozenWatch(20, 0.5)
    became = [
        i for i in range(len(t)) if watch.push(ORIGIN_NS + round(t[i] * 1e9), tuple(wrench[i]))
    ]
    assert became == [1000 + 50]  # frozen once the run spans 0.5 s (51 samples at 100 Hz)
    assert watch.episodes == 1 and watch.frozen_samples == 400 and not watch.frozen
    assert frozen_runs(t, wrench, min_samples=0, min_s=0.5) == []  # 0: no check


def test_a_wholly_frozen_recording_is_one_finding() -> None:
    t = np.arange(4476) * 0.01
    trial = Trial("stuck", t, {"R": np.tile([1.5, -2.0, 9.81, 0.1, 0.0, -0.2], (4476, 1))})
    (line,) = trial_findings(trial, min_samples=20, min_s=0.5)
    assert line.startswith("arm R: wrench frozen") and "4476 samples" in line
    assert "44.75 s, 100 % of the samples" in line


def test_arm_health_warns_while_the_sensor_is_frozen() -> None:
    health, watch, tare = ArmHealth("R"), FrozenWatch(20, 0.5), Tare(0.5)
    for i in range(100):  # 1 s of one value at 100 Hz
        watch.push(ORIGIN_NS + i * 10_000_000, (1.0, 2.0, 3.0, 0.0, 0.0, 0.0))
    status = health.report(1.0, 100, {}, {}, 1.0, True, watch, tare, 0)
    assert status.level == WARN and "wrench frozen" in status.message
    assert "for 100 samples (0.99 s)" in status.message
    values = dict(status.values)
    assert values["frozen now"] == "yes" and values["frozen episodes"] == "1"
    assert values["tare offsets"] == "none" and values["tares completed"] == "0"
    watch.push(ORIGIN_NS + 10**9, (1.5, 2.0, 3.0, 0.0, 0.0, 0.0))  # moves again
    assert health.report(1.0, 101, {}, {}, 1.0, True, watch, tare, 0).level == OK


# --------------------------------------------------------------------------- repeated stamps


def test_session_counts_a_resent_rejected_sample_as_a_duplicate() -> None:
    """Stamps 20, 20, 20 with values 2, 3, 3: a repeated stamp, then a re-sent copy of it, live
    as in the batch rule (the copy is compared with the rejected sample, not the accepted one)."""
    t = np.array([10, 20, 20, 20])
    y = np.array([1.0, 2.0, 3.0, 3.0])[:, None].repeat(6, axis=1)
    _, _, counts = resolve_repeated_stamps(t, y, "reject")
    session = SegmenterSession(("R",), arm_stream_factory())
    for stamp, row in zip(t, y, strict=True):
        session.push("R", ORIGIN_NS + int(stamp) * 1_000_000, row.tolist())
    rejected = session.counts["R"].rejected
    assert rejected["duplicate_sample"] == counts["duplicate_sample"] == 1
    assert rejected["repeated_stamp"] == counts["repeated_stamp"] == 1


def test_repeated_stamps_by_hand() -> None:
    t = np.array([0, 10, 10, 10, 20, 30, 30])
    y = np.arange(7.0)[:, None].repeat(6, axis=1)
    y[3] = y[2]  # a re-sent message: dropped under every policy
    kept_t, kept_y, counts = resolve_repeated_stamps(t, y, "reject")
    assert kept_t.tolist() == [0, 10, 20, 30] and kept_y[:, 0].tolist() == [0, 1, 4, 5]
    assert counts == {"duplicate_sample": 1, "repeated_stamp": 2, "respaced_stamps": 0}
    kept_t, kept_y, counts = resolve_repeated_stamps(t, y, "spread")
    assert kept_t.tolist() == [0, 10, 15, 20, 30]  # the last one has no later stamp: dropped
    assert kept_y[:, 0].tolist() == [0, 1, 2, 4, 5]
    assert counts == {"duplicate_sample": 1, "repeated_stamp": 1, "respaced_stamps": 1}


@pytest.mark.parametrize("policy", ["reject", "spread"])
def test_session_resolves_repeated_stamps_as_the_batch_reader(policy: RepeatedPolicy) -> None:
    """~100 Hz with 5.5-30 ms jitter and one stamp in eight repeated: the session's words and
    counts equal those of the recording resolved by io/sensor_checks and streamed."""
    stamps, repeats = jittered_stamps(1500, seed=2)
    _, wrench = wrench_signal(1500, 0.01, seed=3)
    wrench[700] = wrench[699]  # a re-sent sample among them (same stamp and values)
    stamps[700] = stamps[699]
    session = SegmenterSession(
        ("R",), arm_stream_factory(), intake=IntakeConfig(repeated_stamps=policy)
    )
    got = feed(session, stamps, wrench)
    kept_ns, kept, counts = resolve_repeated_stamps(stamps, wrench, policy)
    assert got == offline_words((kept_ns - ORIGIN_NS) / 1e9, kept)
    c = session.counts["R"]
    assert c.rejected["duplicate_sample"] == counts["duplicate_sample"] >= 1
    assert c.rejected["repeated_stamp"] == counts["repeated_stamp"]
    assert c.respaced == counts["respaced_stamps"]
    assert c.accepted == len(kept)
    assert counts["repeated_stamp"] + counts["respaced_stamps"] + 1 >= repeats > 100


def test_trial_folders_and_bags_with_repeated_stamps(tmp_path: Path) -> None:
    from rcbht_introspection.io.bags import read_trial_bag, write_trial_bag

    t, wrench = wrench_signal(400, 0.01, seed=4)
    t[[50, 51, 200]] = t[[49, 49, 199]]  # 49, 50, 51 share a stamp; so do 199 and 200
    trial = Trial("rep", t, {"R": wrench}, state_times=(0.0, 1.0, 2.0, 3.0))
    folder = write_trial(trial, tmp_path / "rep")
    with pytest.raises(InputError, match=r"line 51, field t: time does not increase.*repeated"):
        read_trial(folder)
    spread = read_trial(folder, "spread")
    assert len(spread.time) == 400 and bool((np.diff(spread.time) > 0).all())
    assert spread.metadata["repeated_stamps"] == {
        "R": {"duplicate_sample": 0, "repeated_stamp": 0, "respaced_stamps": 3}
    }
    assert len(read_trial(folder, "reject").time) == 397
    (line,) = trial_findings(read_trial(folder, "reject"), 20, 0.5)
    assert line == "arm R: repeated time stamps: 3 samples with a repeated stamp dropped"
    bag = tmp_path / "rep.mcap"
    write_trial_bag(trial, bag)
    with pytest.raises(InputError, match="do not increase at message 50; see --repeated"):
        read_trial_bag(bag)
    from_bag = read_trial_bag(bag, repeated="spread")
    np.testing.assert_allclose(from_bag.time, spread.time, atol=1e-9)


# --------------------------------------------------------------------------- tare


def test_tare_holds_a_window_then_subtracts_its_mean() -> None:
    tare = Tare(0.5)
    assert tare.idle and tare.push(0.0, [1.0] * 6) == [(0.0, [1.0] * 6)]
    tare.request()
    assert [tare.push(k * 0.1, [float(k)] * 6) for k in range(5)] == [[]] * 5  # 0.0 .. 0.4 s
    released = tare.push(0.5, [9.0] * 6)  # closes the window: mean of 0..4 is 2
    assert [t for t, _ in released] == [k * 0.1 for k in range(5)] + [0.5]
    assert [v[0] for _, v in released] == [-2.0, -1.0, 0.0, 1.0, 2.0, 7.0]
    assert tare.completed == 1 and tare.offsets == (2.0,) * 6
    tare.request()  # a re-tare: the next samples are held and get the new offsets
    assert tare.release() == [] and tare.measuring  # no sample yet: the request stays
    assert tare.push(1.0, [4.0] * 6) == []
    assert tare.release() == [(1.0, [0.0] * 6)]  # the end of a stream closes it early
    assert tare.offsets == (4.0,) * 6 and tare.completed == 2


def test_session_tare_at_stream_start_equals_the_tared_recording() -> None:
    t, wrench = wrench_signal(800, 0.005, seed=5)  # 200 Hz, 4 s, with a bias of 3
    stamps = ORIGIN_NS + np.rint(t * 1e9).astype(np.int64)
    state = (0.0, 1.2, 1.6, 2.5)
    events = [(ORIGIN_NS + round(s * 1e9), name) for s, name in
              zip(state, ("approach", "rotation", "insertion", "mating"), strict=True)]  # fmt: skip
    intake = IntakeConfig(tare_at_start=True, tare_window_s=0.5)
    session = SegmenterSession(("R",), arm_stream_factory(), intake=intake)
    got = feed(session, stamps, wrench, events)
    tared = tare_recording(t, wrench, 0.5)
    assert got == offline_words(t, tared, state)
    assert got != offline_words(t, wrench, state)  # the tare changed the words
    np.testing.assert_allclose(np.asarray(session.tares["R"].offsets), wrench[:100].mean(axis=0))
    assert session.tares["R"].completed == 1
    assert session.tares["R"].measuring  # the next stream is tared again


# --------------------------------------------------------------------------- tool gravity


def rot_x(degrees: float) -> np.ndarray:
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def test_gravity_compensation_against_hand_computed_values() -> None:
    # 2 kg at 0.1 m along the sensor's x axis, g = 9.81: weight 19.62 N
    level = gravity_wrench(np.eye(3), 2.0, (0.1, 0.0, 0.0), 9.81)
    # sensor upright: F = (0, 0, -19.62); M = c x F = (0, 0.1 * 19.62, 0)
    np.testing.assert_allclose(level, [0, 0, -19.62, 0, 1.962, 0], atol=1e-12)
    # rolled 90 deg about x: the sensor's y axis points up, so F = (0, -19.62, 0), M = (0, 0, -1.962)
    rolled = gravity_wrench(rot_x(90), 2.0, (0.1, 0.0, 0.0), 9.81)
    np.testing.assert_allclose(rolled, [0, -19.62, 0, 0, 0, -1.962], atol=1e-12)
    measured = np.array([1.0, -18.62, 0.5, 0.2, 0.0, -1.962])
    np.testing.assert_allclose(
        compensate_gravity(measured, rot_x(90), 2.0, (0.1, 0.0, 0.0), 9.81),
        [1.0, 1.0, 0.5, 0.2, 0.0, 0.0],
        atol=1e-12,
    )
    stacked = compensate_gravity(np.zeros((2, 6)), np.stack([np.eye(3), rot_x(90)]), 2.0,
                                 (0.1, 0.0, 0.0), 9.81)  # fmt: skip
    np.testing.assert_allclose(stacked, -np.stack([level, rolled]), atol=1e-12)
    half = math.sqrt(0.5)
    np.testing.assert_allclose(rotation_from_quaternion(half, 0, 0, half), rot_x(90), atol=1e-12)
    with pytest.raises(ValueError, match="not finite"):  # it would make every sample NaN
        rotation_from_quaternion(math.inf, 0, 0, 1)


def test_session_needs_a_pose_then_subtracts_the_tool_weight() -> None:
    t, wrench = wrench_signal(600, 0.005, seed=6)
    stamps = ORIGIN_NS + np.rint(t * 1e9).astype(np.int64)
    intake = IntakeConfig(tool_mass_kg=2.0, tool_com_m=(0.1, 0.0, 0.0), gravity_m_s2=9.81)
    session = SegmenterSession(("R",), arm_stream_factory(), intake=intake)
    assert session.push("R", ORIGIN_NS - 10**9, wrench[0]).rejected == "no_pose"
    session.pose("R", rot_x(90))
    got = feed(session, stamps, wrench)
    assert session.counts["R"].rejected["no_pose"] == 1
    assert got == offline_words(t, wrench - gravity_wrench(rot_x(90), 2.0, (0.1, 0.0, 0.0), 9.81))


# --------------------------------------------------------------------------- configuration


def test_intake_parameters_are_checked_with_file_and_line(tmp_path: Path) -> None:
    from rcbht_introspection.configure.params import (
        SegmenterConfig,
        config_from_parameters,
        defaults,
        load_node_config,
    )

    params = tmp_path / "segmenter.yaml"
    params.write_text(
        "segmenter_node:\n  ros__parameters:\n    intake:\n      tare_at_start: true\n"
        "      frozen_s: -1.0\n"
    )
    with pytest.raises(InputError) as info:
        load_node_config(SegmenterConfig, params)
    assert str(info.value) == (
        f"{params}, line 5, field segmenter_node.ros__parameters.intake.frozen_s: "
        "must be in [0, 3600], got -1.0"
    )
    # ROS parameters arrive with dotted names
    cfg = config_from_parameters(SegmenterConfig, {**defaults(SegmenterConfig),
                                                   "intake.repeated_stamps": "spread"})  # fmt: skip
    assert cfg.intake == IntakeConfig(repeated_stamps="spread")
    with pytest.raises(InputError, match="field pose_topics: gravity compensation needs both"):
        config_from_parameters(
            SegmenterConfig, {**defaults(SegmenterConfig), "intake.tool_mass_kg": 1.0}
        )


# --------------------------------------------------------------------------- batch commands


def four_subtask_trial(folder: Path, seed: int, frozen: slice | None = None) -> Path:
    """A generated one-arm trial folder (200 Hz, 6 s, four sub-tasks), optionally frozen."""
    t, wrench = wrench_signal(1200, 0.005, seed)
    if frozen is not None:
        wrench[frozen] = wrench[frozen.start]
    return write_trial(Trial(folder.name, t, {"R": wrench}, (0.0, 1.5, 3.0, 4.5)), folder)


def test_label_and_train_warn_about_a_frozen_trial(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = tmp_path / "set"
    for k in range(3):
        four_subtask_trial(data / f"T{k}", seed=10 + k, frozen=slice(200, 500) if k == 1 else None)
    assert main(["label", str(data), "--out", str(tmp_path / "out")]) == 0
    label_err = capsys.readouterr().err.splitlines()
    assert label_err == [
        "rcbht label: warning: T1: arm R: wrench frozen: the same values "
        f"({', '.join(f'{v:.4g}' for v in read_trial(data / 'T1').wrench['R'][200])}) "
        "for 300 samples (1.50 s, 25 % of the samples) from 1.000 s"
    ]
    model = tmp_path / "m.rcbht"
    args = ["train", str(data), "--out", str(model), "--words", "engine", "--no-live-augment"]
    assert main(args) == 0
    err = capsys.readouterr().err
    assert "rcbht train: warning: T1: arm R: wrench frozen" in err and "T0" not in err

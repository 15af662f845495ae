"""The soak benchmark: its message encoding and schedule, and a short run end to end.

The short run checks structure and correctness (no drops, clean exits, a restarted classifier
that classifies); its speed and memory figures are measurements and are never asserted.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from ros_support import require_ros

pytestmark = [pytest.mark.ros]


def test_wrench_cdr_is_what_rclpy_reads_and_writes() -> None:
    """io/bags encode_wrench / decode_wrench against rclpy's own (de)serialisation."""
    require_ros()
    from geometry_msgs.msg import WrenchStamped
    from rclpy.serialization import deserialize_message, serialize_message

    from rcbht_introspection.io.bags import decode_wrench, decode_wrench_sample, encode_wrench

    for frame in ("L", "R", "", "a_longer_frame"):
        msg = WrenchStamped()
        msg.header.stamp.sec, msg.header.stamp.nanosec = 1_700_000_001, 999_999_999
        msg.header.frame_id = frame
        msg.wrench.force.x, msg.wrench.force.z, msg.wrench.torque.y = 1.5, -20.25, 1e-9
        values = (1.5, 0.0, -20.25, 0.0, 1e-9, 0.0)
        raw = encode_wrench(1_700_000_001_999_999_999, frame, values)
        assert deserialize_message(raw, WrenchStamped) == msg
        assert len(raw) == len(serialize_message(msg))
        rclpy_raw = serialize_message(msg)
        assert decode_wrench(rclpy_raw) == (1_700_000_001_999_999_999, frame, values)
        assert decode_wrench_sample(rclpy_raw) == (1_700_000_001_999_999_999, values)


def test_playback_is_the_trial_bag_order(tmp_path: Path) -> None:
    """Samples, sub-task events and the end event come in a trial bag's order, re-stamped."""
    from rcbht_introspection.bench.ros import synthetic_trial, two_arm_trial
    from rcbht_introspection.bench.soak_traffic import ARMS, playback
    from rcbht_introspection.io.bags import (
        PHASE_TOPIC,
        WRENCH_TYPE,
        bag_messages,
        decode_string,
        write_trial_bag,
    )

    trial = two_arm_trial(synthetic_trial("a", 3.0, 1), synthetic_trial("b", 3.0, 2))
    base = 1_800_000_000 * 10**9
    write_trial_bag(trial, tmp_path / "t.mcap", time_origin_ns=base)
    expected = [
        m.raw if m.msgtype == WRENCH_TYPE else decode_string(m.raw)
        for m in bag_messages(tmp_path / "t.mcap")
        if m.msgtype == WRENCH_TYPE or m.topic == PHASE_TOPIC
    ]
    pb = playback(trial, base, rate=5.0)
    got: list[bytes | str] = []
    for i, raws in enumerate(pb.raws):
        assert len(raws) == len(ARMS)
        got += raws
        got += pb.events.get(i, [])
    assert got == expected
    assert pb.offsets[-1] == pytest.approx(trial.end_time / 5.0)
    assert pb.last_stamp_ns == base + round(trial.end_time * 1e9)


def test_rss_growth_over_the_last_window() -> None:
    from rcbht_introspection.bench.process_watch import growth

    samples = [(0.0, 100.0, 0.0), (10.0, 150.0, 1.0), (20.0, 150.0, 2.0), (30.0, 153.0, 3.0)]
    g = growth(samples, 20.0)
    assert g["window_s"] == 20.0
    assert g["growth_pct"] == pytest.approx(2.0)
    assert growth(samples[:1], 20.0)["growth_pct"] is None


@pytest.mark.slow
def test_soak_short(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, bench_model: Path | None
) -> None:
    """25 s of 2 x 1 kHz through both nodes with a classifier restart at a quarter of the run."""
    require_ros()
    from rcbht_introspection.bench import soak

    monkeypatch.setenv("RCBHT_SOAK_SECONDS", "25")
    monkeypatch.setenv("RCBHT_SOAK_SAMPLE_S", "5")
    monkeypatch.setenv("RCBHT_SOAK_RESTART_AT", "0.25")
    if bench_model is not None:  # the session's copy of the model run() would train
        monkeypatch.setenv("RCBHT_SOAK_MODEL", str(bench_model))
    r = soak.run(tmp_path)
    assert r["model"] == (str(bench_model) if bench_model else None)
    assert r["aborted"] is None, r.get("aborted_log_tail")
    assert r["publisher_error"] is None
    assert r["arms"] == ["L", "R"]
    # every sample published reached the segmenter and was accepted
    for arm in ("L", "R"):
        assert r["wrench_published"][arm] > 0
        assert r["wrench_accepted"][arm] == r["wrench_published"][arm]
        assert r["wrench_rejected"][arm] == 0
        assert r["streams_ended"][arm] == r["trials"] == r["end_events_published"]
    assert r["wrench_dropped"] == 0
    assert r["events_applied"] == {
        "subtask": r["subtask_events_published"],
        "end": r["end_events_published"],
    }
    # the classifier was stopped cleanly mid-run and its successor classified
    restart = r["restart"]
    assert "error" not in restart, restart.get("error")
    assert restart["exit_code"] == 0
    assert r["verdicts"]["classifier_node_2"] > 0
    assert r["exit_codes"] == {"segmenter_node": 0, "classifier_node_1": 0, "classifier_node_2": 0}
    assert r["unclean_exits"] == 0
    # the figures are there (their values are measurements, not asserted)
    for name in ("segmenter_node", "classifier_node_1", "classifier_node_2", "soak_driver"):
        p = r["processes"][name]
        assert len(p["rss_mib"]) >= 2
        assert all(t >= 0 and rss > 0 for t, rss in p["rss_mib"])
        assert set(p) >= {"growth_pct", "window_s", "rss_peak_mib", "cpu_pct", "exit_code"}
    assert set(r["rss_bounded_5pct"]) == {
        "segmenter_node",
        "classifier_node_1",
        "classifier_node_2",
    }
    assert r["machine"]["cores"] and len(r["load_avg_series"]) >= 2
    assert set(r["achieved_rate_hz_per_arm"]) == {"L", "R"}
    assert (tmp_path / "soak" / "progress.json").is_file()

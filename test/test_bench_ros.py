"""The ROS benchmark runs end to end with a short duration (figures are measured, not asserted)."""

from __future__ import annotations

from pathlib import Path

import pytest
from ros_support import require_ros

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def test_ros_benchmark_short(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, bench_model: Path | None
) -> None:
    require_ros()
    from rcbht_introspection.bench import ros

    monkeypatch.setenv("RCBHT_BENCH_ROS_SECONDS", "2")
    monkeypatch.setenv("RCBHT_BENCH_ROS_SPINS", "events")  # the fallback: test_ros_e2e
    if bench_model is not None:  # the session's copy of the model run() would train
        monkeypatch.setenv("RCBHT_BENCH_ROS_MODEL", str(bench_model))
    result = ros.run(tmp_path)
    floor = result["dds_floor_1kHz"]
    assert floor["published"] == 2 * 1000 and floor["exit_codes"] == [0, 0]
    assert 0 <= floor["dropped"] < floor["published"] == floor["latency_ms"]["n"] + floor["dropped"]
    assert floor["latency_ms"]["p50"] > 0
    scenarios = [(n, a, spin) for n, a, v, spin in ros.SCENARIOS if not v and spin == "events"]
    assert len(scenarios) == 2 and not any(
        n in result for n, *_ in ros.SCENARIOS if n.endswith("executor")
    )
    for name, arms, spin in scenarios:
        r = result[name]
        assert r["arms"] == arms and r["spin"] == spin
        cpu = r["cpu_us_per_sample"]
        assert set(cpu) == {"segmenter_node", "classifier_node"} and min(cpu.values()) > 0
        assert r["wrench_published"] >= 2 * 1000 * arms * 0.9
        assert 0 <= r["wrench_dropped"] <= r["wrench_published"]
        assert r["achieved_rate_hz_per_arm"] > 500
        assert r["latency_ms"]["n"] > 0 and r["word_latency_ms"]["n"] > 0
        assert r["clean_shutdown"], (r["exit_codes"], r["shutdown_logs"])
        ratio = r["latency_ms"]["p99"] / floor["latency_ms"]["p99"]
        assert r["latency_p99_over_floor"] == pytest.approx(ratio, abs=0.01)
    v = result["one_arm_1kHz_verifier"]
    assert v["clean_shutdown"], (v["exit_codes"], v["shutdown_logs"])
    assert v["sample_to_verdict_ms"]["n"] > 0 and v["latency_ms"]["n"] > 0
    assert v["verdicts"] > 0
    assert result["model"] == (str(bench_model) if bench_model else None)
    # three trials: the second played while the first is learned
    t = result["one_arm_1kHz_teaching"]
    assert t["taught_trials"] == 2 and t["teach_errors"] == 0 and t["clean_shutdown"]
    assert t["latency_beside_teaching_ms"]["n"] > 0 and t["latency_taught_model_ms"]["n"] > 0

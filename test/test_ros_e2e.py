"""End to end over real DDS: converted HIRO trials replayed through both node processes, scored
against the truth and the offline run of the same stream and model (`rcbht train`'s default on
the other trials, 1-40: the session's bench_model)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from ros_support import require_ros

from rcbht_introspection.cli import main
from rcbht_introspection.configure.spin import Spin

pytestmark = [pytest.mark.ros, pytest.mark.shared_data, pytest.mark.slow]

HELD_OUT = (41, 44)


@pytest.fixture
def model(hiro_data: Path, bench_model: Path | None) -> Path:
    """The model of REAL 1-40 (present: hiro_data requires the shared data)."""
    assert bench_model is not None, f"no model made from {hiro_data}"
    return bench_model


def test_replay_eval_of_held_out_trials(hiro_data: Path, model: Path, tmp_path: Path) -> None:
    require_ros()
    real = hiro_data / "REAL_HIRO_ONE_SA_SUCCESS"
    bags = []
    for i in HELD_OUT:
        bag = tmp_path / f"s{i}.mcap"
        assert main(["bag", "from-hiro", str(real / f"20121127-HIROSA-S-{i:02d}"), str(bag)]) == 0
        bags.append(str(bag))
    out = tmp_path / "eval.json"
    assert (
        main(["replay-eval", *bags, "--model", str(model), "--rate", "5", "--json", str(out)]) == 0
    )
    result = json.loads(out.read_text())
    assert result["clean_shutdown"], (result["exit_codes"], result.get("shutdown_logs"))
    assert result["dropped_wrench"] == 0
    assert result["words_match_offline"], [b["words_mismatch"] for b in result["per_bag"]]
    assert result["verdicts_match_offline"], [
        (b["verdicts"], b["offline_verdicts"]) for b in result["per_bag"]
    ]
    # /task_state follows the nodes' own sessions run offline on the same inputs; DDS does not
    # order messages across topics, so under load an event can reach the classifier after words
    # published after it and a short state can differ (CI saw S-41's 0.3 s 'rotation' go): the
    # match is reported, and the number of changes must stay within 2 of offline
    assert abs(result["state_changes"] - result["offline_state_changes"]) <= 2, [
        (b["timeline"], b["offline_timeline"]) for b in result["per_bag"]
    ]
    assert result["subtasks"] == 4 * len(HELD_OUT)
    assert result["subtask_accuracy"] >= 0.75
    assert 0.0 < result["time_accuracy"] <= 1.0
    assert result["latency_ms"]["n"] > 100 and result["latency_ms"]["p50"] > 0
    for b in result["per_bag"]:
        assert b["published_wrench"] > 5000 and b["node_words"] == b["offline_words"] > 0


@pytest.mark.parametrize("spin", ["events", "executor"])
def test_two_arm_replay_matches_offline(
    hiro_data: Path, model: Path, tmp_path: Path, spin: Spin
) -> None:
    """Two arms (/L/wrench, /R/wrench at 2 x 1 kHz): per-arm words, verdicts, beliefs and
    /task_state as offline, whichever executor spins the nodes."""
    require_ros()
    from rcbht_introspection.bench.ros import two_arm_trial
    from rcbht_introspection.io.bags import write_trial_bag
    from rcbht_introspection.io.hiro import read_trial
    from rcbht_introspection.replay.harness import ReplayEvalOptions, replay_eval

    real = hiro_data / "REAL_HIRO_ONE_SA_SUCCESS"
    trial = two_arm_trial(
        read_trial(real / "20121127-HIROSA-S-44"), read_trial(real / "20121127-HIROSA-S-45")
    )
    write_trial_bag(trial, tmp_path / "two.mcap")
    result = replay_eval([tmp_path / "two.mcap"], model, ReplayEvalOptions(rate=5, spin=spin))
    bag = result["per_bag"][0]
    assert result["words_match_offline"], bag["words_mismatch"]
    assert result["verdicts_match_offline"], (bag["verdicts"], bag["offline_verdicts"])
    assert abs(result["state_changes"] - result["offline_state_changes"]) <= 2, (
        bag["timeline"],
        bag["offline_timeline"],
    )
    assert result["dropped_wrench"] == 0
    assert result["clean_shutdown"], (result["exit_codes"], result.get("shutdown_logs"))
    assert bag["published_wrench"] == 2 * len(trial.time)

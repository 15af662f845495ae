"""Teaching over real DDS: a classifier_node started without a model is taught five REAL trials
one by one through its ~/teach service, then classifies the held-out REAL 41-43; restarted from
the model it saved, it gives the same verdicts (rcbht replay-eval --teach-first).

The five are S-36..40: the early recordings differ from the late ones (a batch Mondrian forest or
SVM trained offline on S-01..10 or S-11..20 swaps rotation and insertion on S-41..46, accuracy
0.25-0.5; on S-21..30 or S-31..40 it is 1.0), so early trials would test the data, not teaching.
Five taught trials already classify all 24 sub-tasks of S-41..46 right offline; three held-out
bags (12 verdicts, each also replayed after the restart) keep the test's DDS time small."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from ros_support import env, require_ros, start_node

from rcbht_introspection.cli import main

pytestmark = [pytest.mark.ros, pytest.mark.slow]
__all__ = ["env"]  # the isolated-ROS fixture, used by name

TAUGHT = range(36, 41)
HELD_OUT = range(41, 44)
RATE = 10.0
"""Playback speed: the verdicts wait for every word, so a fast replay scores as a real-time one
(the replay harness compares them with the offline run of the saved model). At 20x (4 kHz of
wrench) beside the learner and a busy machine the segmenter's queue overflowed once in CI."""


@pytest.mark.shared_data
def test_cold_started_classifier_learns_through_the_service(
    hiro_data: Path, tmp_path: Path
) -> None:
    require_ros()
    real = hiro_data / "REAL_HIRO_ONE_SA_SUCCESS"
    bags = []
    for i in (*TAUGHT, *HELD_OUT):
        bag = tmp_path / f"s{i:02d}.mcap"
        assert main(["bag", "from-hiro", str(real / f"20121127-HIROSA-S-{i:02d}"), str(bag)]) == 0
        bags.append(str(bag))
    out = tmp_path / "eval.json"
    saved = tmp_path / "taught.rcbht"
    args = ["replay-eval", *bags, "--teach-first", str(len(TAUGHT)), "--teach-restart"]
    args += ["--teach-beside"]  # each taught bag is learned while the next one plays
    args += ["--teach-file", str(saved), "--rate", str(RATE), "--json", str(out)]
    assert main(args) == 0
    result = json.loads(out.read_text())
    teach = result["teach"]
    assert teach["taught_trials"] == [f"20121127-HIROSA-S-{i:02d}" for i in TAUGHT]
    assert teach["taught_windows"] == 4 * len(TAUGHT) and teach["errors"] == 0
    # every taught bag but the first was played while the one before it was being learned
    assert teach["latency_beside_ms"]["n"] > 0
    assert result["clean_shutdown"], (result["exit_codes"], result.get("shutdown_logs"))
    assert result["dropped_wrench"] == 0
    assert result["subtasks"] == 4 * len(HELD_OUT)
    assert result["subtask_accuracy"] >= 0.9, [b["verdicts"] for b in result["per_bag"]]
    # the live verdicts are those of the saved model run offline on the same words
    assert result["words_match_offline"], [b["words_mismatch"] for b in result["per_bag"]]
    assert result["verdicts_match_offline"], [
        (b["verdicts"], b["offline_verdicts"]) for b in result["per_bag"]
    ]
    # restarted from its file, the classifier continues with the taught model
    assert result["restart"]["verdicts_equal"], result["restart"]
    assert saved.is_file()


def test_cold_start_cli_and_topic_refusals(
    tmp_path: Path,
    env: dict[str, str],
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """No model file yet: info-level cold start; `rcbht teach` answers; bad labels are counted."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rcbht_interfaces.msg import TeachRequest

    from rcbht_introspection.nodes.common import qos_profile
    from rcbht_introspection.replay.supervision import stop_process
    from rcbht_introspection.rostools.session import RosSession
    from rcbht_introspection.waiting import wait_until

    monkeypatch.setenv("ROS_DOMAIN_ID", env["ROS_DOMAIN_ID"])  # the CLI's own session
    model = tmp_path / "taught.rcbht"
    params: dict[str, object] = {"teach_enabled": True, "model_file": str(model)}
    log = tmp_path / "classifier.log"
    proc = start_node("classifier_node", params, env, log)
    refused: list[int] = []
    learner: list[str] = []

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if "teach requests refused" in values:
                refused.append(int(values["teach requests refused"]))
                learner.append(values["teach learner"])

    try:
        with RosSession("probe", domain_id=int(env["ROS_DOMAIN_ID"])) as ros:
            ros.node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
            assert wait_until(lambda: refused, timeout=60), log.read_text()  # active, teaching
            assert main(["teach", "--status"]) == 0
            assert "accepted: status (pending 0, taught windows 0" in capsys.readouterr().out
            assert main(["teach", "approach", "--last"]) == 1  # nothing has ended yet
            assert "refused: unknown window" in capsys.readouterr().out
            pub = ros.node.create_publisher(
                TeachRequest, "rcbht/teach", qos_profile(100, "reliable")
            )
            assert wait_until(lambda: pub.get_subscription_count() > 0), log.read_text()
            pub.publish(TeachRequest(label=""))  # fire and forget: an empty label is refused
            assert wait_until(lambda: refused and refused[-1] >= 2, timeout=20), log.read_text()
        assert proc.poll() is None
    finally:
        code = stop_process(proc, timeout=15)
    text = log.read_text()
    assert "cold start: no model yet" in text and "no usable model" not in text
    assert "empty label" in text
    assert code == 0, text
    assert not model.exists()  # nothing taught, nothing saved
    # it learned in a process of its own (config/teach.yaml), which ended with the node
    kind, pid = learner[-1].split()
    assert kind == "process"
    with pytest.raises(ProcessLookupError):
        os.kill(int(pid), 0)

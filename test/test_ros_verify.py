"""verifier_node over real DDS: held-out simulated bags of the repeated-program cell replayed
through the node processes (`rcbht replay-eval --verifier`); its alarms on /task_health and
rcbht/verdict must be those of the offline verifier on the same trials, the failing bags must
raise it within the anchors' 1 s gate after the labelled onset, and the nominal bag never."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from ros_support import require_ros
from verify_support import cell_verifier

from rcbht_introspection.cli import main
from rcbht_introspection.io.bags import write_trial_bag
from rcbht_introspection.verify.evaluate import GATE_S
from rcbht_introspection.verify.labels import label_of
from rcbht_introspection.verify.model_file import load_verifier
from rcbht_introspection.verify.stream import offline_verdicts

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def test_replayed_failures_raise_the_alarm_as_offline_within_the_gate(tmp_path: Path) -> None:
    require_ros()
    verifier, held_out = cell_verifier(tmp_path)
    bags = []
    for trial in held_out:
        bags.append(tmp_path / f"{trial.name}.mcap")
        write_trial_bag(trial, bags[-1])
    out = tmp_path / "eval.json"
    args = ["replay-eval", *map(str, bags), "--verifier", str(verifier), "--rate", "10"]
    assert main([*args, "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["clean_shutdown"], (result["exit_codes"], result.get("shutdown_logs"))
    assert result["dropped_wrench"] == 0
    model = load_verifier(verifier)
    runs = result["verifier"]["runs"]
    assert [r["trial"] for r in runs] == [t.name for t in held_out]
    alarmed = 0
    for trial, run in zip(held_out, runs, strict=True):
        offline = offline_verdicts(trial, model)
        assert run["verdicts"] == len(offline)
        assert run["alarm_time"] == offline[-1].alarm_time, run
        assert run["final_class"] == (offline[-1].failure_class if offline[-1].alarm else "")
        assert run["health_seen"][0] == "nominal", run
        if offline[-1].alarm:  # the alarm reached the health topic, as the class or 'anomaly'
            assert run["health_seen"][-1] == offline[-1].health != "nominal", run
        else:
            assert run["health_seen"] == ["nominal"], run
        label = label_of(trial)
        if label.failed:  # raised within the gate after the labelled onset, not before it
            assert label.onset is not None and run["alarm_time"] is not None, run
            assert 0.0 <= run["alarm_time"] - label.onset <= GATE_S, (label.onset, run)
            alarmed += 1
        else:  # the nominal bag: never an alarm
            assert run["alarm_time"] is None, run
    assert alarmed == 2
    summary = result["verifier"]["summary"]
    assert summary["nominal_runs"] == 1 and summary["failure_runs"] == 2

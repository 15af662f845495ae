"""The /task_state rule (live/state.py) on synthetic belief sequences, its config, and the ECE."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from sklearn.calibration import calibration_curve

from rcbht_introspection.configure.params import ClassifierConfig, load_node_config
from rcbht_introspection.errors import InputError
from rcbht_introspection.live.belief import UNKNOWN, Belief
from rcbht_introspection.live.reliability import expected_calibration_error, top_label
from rcbht_introspection.live.state import StateFilter, TaskStateConfig

CLASSES = ("approach", "insertion", "mating", "rotation")


def belief(leading: str, p: float, blind: bool = False, **others: float) -> Belief:
    """A running belief whose leading class `leading` has probability p (the rest shared, or
    as given in `others`)."""
    if leading == UNKNOWN:
        return Belief(UNKNOWN, CLASSES, (0.0,) * 4, 0.0, 0.0, "boundary", blind=blind)
    rest = [c for c in CLASSES if c != leading and c not in others]
    share = (1 - p - sum(others.values())) / max(1, len(rest))
    probs = tuple(p if c == leading else others.get(c, share) for c in CLASSES)
    return Belief(leading, CLASSES, probs, 0.0, 0.0, "boundary", n_words=10)


def states(f: StateFilter, beliefs: list[tuple[float, Belief]]) -> list[tuple[float, str]]:
    return [(t, f.state) for t, b in beliefs if f.update(t, b)]


def test_unknown_until_the_first_confident_belief() -> None:
    f = StateFilter(TaskStateConfig(min_probability=0.6))
    seq = [(0.0, belief(UNKNOWN, 0)), (0.02, belief("insertion", 0.45)),
           (0.05, belief("approach", 0.59)), (0.1, belief("approach", 0.8))]  # fmt: skip
    assert states(f, seq) == [(0.1, "approach")]


def test_switch_only_past_the_evidence_bound() -> None:
    # log-odds of p = 0.8 is log 4 = 1.386 per belief: 2 beliefs 2.77 < 3 <= 3 beliefs 4.16
    f = StateFilter(TaskStateConfig(min_probability=0.0, evidence_bound=3.0))
    seq = [(0.0, belief("approach", 0.8)), (0.1, belief("approach", 0.8)),
           (0.2, belief("approach", 0.8)), (0.3, belief("mating", 0.8)),
           (0.4, belief("approach", 0.9)), (0.5, belief("mating", 0.8)),
           (0.6, belief("mating", 0.8)), (0.7, belief("mating", 0.8))]  # fmt: skip
    # the 'approach' belief at 0.4 (the state) resets the evidence for 'mating'
    assert states(f, seq) == [(0.2, "approach"), (0.7, "mating")]


def test_log_ratio_over_the_current_state() -> None:
    f = StateFilter(TaskStateConfig(min_probability=0.5, min_log_ratio=1.0))
    seq = [
        (0.0, belief("approach", 0.9)),
        (0.1, belief("mating", 0.55, approach=0.4)),  # log(0.55/0.4) = 0.32 < 1
        (0.2, belief("mating", 0.7, approach=0.2)),
    ]  # log(0.7/0.2) = 1.25 >= 1
    assert states(f, seq) == [(0.0, "approach"), (0.2, "mating")]  # fmt: skip


def test_no_flip_to_unknown_at_a_boundary_but_a_blind_window_is_unknown() -> None:
    f = StateFilter(TaskStateConfig(min_probability=0.6))
    seq = [
        (0.0, belief("approach", 0.9)),
        (5.0, belief(UNKNOWN, 0)),  # a sub-task event: an empty window, no evidence
        (5.05, belief("insertion", 0.5)),  # not confident: the state stays
        (5.1, belief("insertion", 0.9)),
        (9.0, belief(UNKNOWN, 0, blind=True)),
    ]  # words proven lost
    assert states(f, seq) == [(0.0, "approach"), (5.1, "insertion"), (9.0, UNKNOWN)]  # fmt: skip


def test_hold_still_debounces() -> None:
    f = StateFilter(TaskStateConfig(min_probability=0.0, hold_s=0.1))
    seq = [(0.0, belief("insertion", 0.5)), (0.05, belief("approach", 0.5)),
           (0.12, belief("approach", 0.5)), (0.16, belief("approach", 0.5)),
           (5.0, belief("rotation", 0.5)), (5.05, belief("insertion", 0.5)),
           (5.1, belief("insertion", 0.5)), (5.16, belief("insertion", 0.5))]  # fmt: skip
    assert states(f, seq) == [(0.16, "approach"), (5.16, "insertion")]


def test_a_new_stream_keeps_the_state_and_drops_the_pending_candidate() -> None:
    """A stream's start is a sub-task boundary: the state stays until a confident belief (the
    old stream's half-held candidate does not carry over)."""
    f = StateFilter(TaskStateConfig(min_probability=0.6, hold_s=0.1))
    assert f.update(0.0, belief("mating", 0.9)) is False  # pending: held 0 s
    assert f.update(0.2, belief("mating", 0.9)) and f.state == "mating"
    assert not f.update(9.0, belief("approach", 0.9))  # a candidate, held 0 s
    f.new_stream()
    assert f.state == "mating"
    assert not f.update(0.0, belief(UNKNOWN, 0)) and f.state == "mating"  # no evidence yet
    assert not f.update(0.05, belief("approach", 0.9))  # a new candidate from 0.05 s
    assert f.update(0.2, belief("approach", 0.9)) and f.state == "approach"


def test_the_rule_is_configured_in_the_classifier_parameters(tmp_path: Path) -> None:
    assert load_node_config(ClassifierConfig).state == TaskStateConfig()
    bad = tmp_path / "classifier.yaml"
    bad.write_text("classifier_node:\n  ros__parameters:\n    state:\n      min_probability: 1.5\n")
    with pytest.raises(
        InputError, match=r"line 4, field \S*state\.min_probability: must be in \[0, 1\]"
    ):
        load_node_config(ClassifierConfig, bad)
    with pytest.raises(InputError, match="min_log_ratio"):
        StateFilter(TaskStateConfig(min_log_ratio=-1.0))


def test_ece_equals_the_calibration_curve_reference() -> None:
    rng = np.random.default_rng(3)
    conf = rng.uniform(0.25, 1.0, 2000)
    correct = rng.uniform(size=conf.size) < conf**2  # over-confident
    prob_true, prob_pred = calibration_curve(correct, conf, n_bins=10, strategy="uniform")
    counts = np.histogram(conf, bins=np.linspace(0, 1, 11))[0]
    counts = counts[counts > 0]
    reference = float(np.sum(counts / counts.sum() * np.abs(prob_true - prob_pred)))
    assert expected_calibration_error(conf, correct) == pytest.approx(reference, abs=1e-12)
    assert reference > 0.1
    calibrated = rng.uniform(size=conf.size) < conf
    assert expected_calibration_error(conf, calibrated) < 0.05
    assert expected_calibration_error([], []) is None


def test_top_label_confidence_and_correctness() -> None:
    conf, hit = top_label([[0.1, 0.7, 0.2], [0.5, 0.3, 0.2]], ["a", "b", "c"], ["b", "c"])
    assert conf.tolist() == [0.7, 0.5] and hit.tolist() == [True, False]


def test_live_eval_reports_the_state_rule_and_calibration(
    request: pytest.FixtureRequest, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`rcbht live-eval` on generated trials: the JSON keys of the state rule and calibration."""
    from conftest import generated_trials

    from rcbht_introspection.cli import main

    inputs = [str(p) for p in generated_trials(request)[:4]]
    out = tmp_path / "live.json"
    args = ["live-eval", *inputs, "--held-out", "1", "--mode", "boundary", "--json", str(out)]
    assert main([*args, "--state-min-probability", "0.7"]) == 0
    result = json.loads(out.read_text())
    assert result["state_rule"] == dataclasses.asdict(TaskStateConfig(min_probability=0.7))
    assert result["commanded_phase"]["state_changes"] == 4  # 1 trial of 4 sub-tasks
    for key in ("before/boundary", "after/boundary"):
        r = result["results"][key]
        assert r["subtasks"] == 4
        assert r["state_changes_per_boundary"] == round(r["state_changes"] / 4, 3)
        assert r["state_changes"] <= r["without_state_rule"]["state_changes"]
        assert 0.0 <= r["expected_calibration_error"]["final"] <= 1.0
        assert 0.0 <= r["expected_calibration_error"]["running"] <= 1.0
        assert 0.0 <= r["time_accuracy"] <= 1.0
    assert main([*args, "--state-hold-s", "-1"]) != 0
    assert "field --state-hold-s: must be in [0, 10], got -1.0" in capsys.readouterr().err


def test_a_window_of_few_words_does_not_move_the_state() -> None:
    """min_words: a confident belief from a window of fewer words keeps the state."""
    f = StateFilter(TaskStateConfig(min_probability=0.6, min_words=3))
    few = replace(belief("insertion", 0.9), n_words=2)
    assert not f.update(0.1, few) and f.state == UNKNOWN
    assert f.update(0.2, replace(few, n_words=3)) and f.state == "insertion"
    assert not f.update(0.3, replace(belief("mating", 0.95), n_words=1))
    assert f.state == "insertion"


def test_an_evidence_bound_of_zero_is_off() -> None:
    """min_probability 0 and evidence_bound 0: a leading belief below 0.5 moves the state too."""
    f = StateFilter(TaskStateConfig(min_probability=0.0, evidence_bound=0.0, min_words=0))
    assert f.update(0.1, belief("insertion", 0.45)) and f.state == "insertion"

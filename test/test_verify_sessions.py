"""The verifier across recording sessions: trained on the trials of one simulated session, it
raises no alarm on the successes of sessions whose sensor was re-biased and drifts otherwise
(sim/sessions.py), where the raw-wrench baseline alarms."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest

from rcbht_introspection.io.hiro import read_trial
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.sim import load_sim_config, write_dataset
from rcbht_introspection.sim.sessions import draw_sessions, session_of
from rcbht_introspection.verify.config import VERIFIER_SIGNALS, load_verify_config
from rcbht_introspection.verify.detector import Detector
from rcbht_introspection.verify.features import trial_features
from rcbht_introspection.verify.labels import label_of

SESSIONS = 2
PER_SESSION = 20
"""Twenty successes to train on: the conformal threshold then bounds the false alarms near
1 / 21 even before the sessions differ."""


@pytest.fixture(scope="module")
def sessions(tmp_path_factory: pytest.TempPathFactory) -> list[list[Trial]]:
    """Successes of two recording sessions of the repeated-program cell (about 35 s)."""
    root = tmp_path_factory.mktemp("sessions")
    config = load_sim_config(Path(__file__).parents[1] / "config" / "sim/cell.yaml")
    paths = write_dataset(root, SESSIONS * PER_SESSION, seed=41, config=config, sessions=SESSIONS)
    trials = [read_trial(p) for p in paths]
    out: list[list[Trial]] = [[] for _ in range(SESSIONS)]
    for t in trials:
        out[int(label_of(t).session.split("-")[-1]) - 1].append(t)
    return out


def _alarms(detector: Detector, trials: Sequence[Trial]) -> int:
    cfg = detector.config
    return sum(detector.run(trial_features(t, cfg)).alarm is not None for t in trials)


def test_sessions_are_blocks_with_their_own_bias_and_drift() -> None:
    config = load_sim_config().sensor
    draws = draw_sessions(3, 41, config)
    assert [session_of(i, 24, 3) for i in range(24)] == [0] * 8 + [1] * 8 + [2] * 8
    assert [session_of(i, 5, 2) for i in range(5)] == [0, 0, 0, 1, 1]
    for d in draws:
        assert np.all(np.abs(d.bias[:3]) <= config.session_bias_force)
        assert np.all(np.abs(d.bias[3:]) <= config.session_bias_torque)
        assert np.all(np.abs(d.drift[:3]) <= config.session_drift_force)
    assert len({tuple(np.round(d.bias, 6)) for d in draws}) == 3
    assert draws[0].bias == pytest.approx(draw_sessions(3, 41, config)[0].bias)


def test_a_verifier_of_one_session_holds_on_the_others(sessions: list[list[Trial]]) -> None:
    """At most 0.05 false alarms per nominal run on the other sessions' successes; the raw
    wrench by time into the trial, which reads the bias, alarms on most of them."""
    config = load_verify_config()
    train = [trial_features(t, config) for t in sessions[0]]
    others = [t for s in sessions[1:] for t in s]
    levels = [np.mean(s[0].wrench["R"][:20, 2]) for s in sessions]
    assert max(levels) - min(levels) > 1.0, "the sessions' sensors read different levels"
    verifier = Detector.fit(train, config, VERIFIER_SIGNALS)
    assert _alarms(verifier, others) / len(others) <= 0.05
    raw = Detector.fit(train, config, ("wrench_global",))
    assert _alarms(raw, others) / len(others) > 0.5

"""Recording sessions of a simulated set: the sensor re-biased and drifting differently each day.

Trials are split into `sessions` consecutive blocks; each session draws a constant bias and a
linear drift per axis (uniform within the sensor config's session ranges) from its own seed, and
every trial of it carries them on top of its own sensor errors, with its session's name in the
metadata (what verify's session-grouped calibration reads).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.hiro import SESSION_RECORD
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.sim.arm_config import SensorConfig


@dataclass(frozen=True)
class SessionSensor:
    """One session's sensor: a bias (6,) and a drift per second (6,)."""

    name: str
    bias: NDArray[np.float64]
    drift: NDArray[np.float64]


def draw_sessions(sessions: int, seed: int, config: SensorConfig) -> list[SessionSensor]:
    """The draws of `sessions` sessions (a generator of their own: the trials' draws are
    unchanged)."""
    if sessions < 1:
        raise InputError(f"need at least one session, got {sessions}", field="sessions")
    force = np.array([1.0] * 3 + [0.0] * 3)
    bias = force * config.session_bias_force + (1 - force) * config.session_bias_torque
    drift = force * config.session_drift_force + (1 - force) * config.session_drift_torque
    rng = np.random.default_rng([seed, 0x5E55])
    return [
        SessionSensor(
            f"session-{k + 1:02d}", rng.uniform(-1, 1, 6) * bias, rng.uniform(-1, 1, 6) * drift
        )
        for k in range(sessions)
    ]


def session_of(index: int, n_trials: int, sessions: int) -> int:
    """The session of trial `index` of `n_trials`: consecutive blocks of nearly equal size."""
    return index * sessions // n_trials


def in_session(trial: Trial, session: SessionSensor) -> Trial:
    """The trial as its session's sensor records it."""
    t = np.asarray(trial.time, dtype=float)
    offset = session.bias[None, :] + (t - t[0])[:, None] * session.drift[None, :]
    wrench = {arm: np.asarray(w) + offset for arm, w in trial.wrench.items()}
    return replace(trial, wrench=wrench, metadata={**trial.metadata, SESSION_RECORD: session.name})

"""Seeded trials of both simulated tasks stay bit-identical: a refactoring of the shared arm code
(sim/arm_*.py) or of a task's modules must not move a single sample.

The digests were computed from the code before the snap and peg modules shared their config bases,
plan draws and controller steps; they pin this machine's MuJoCo build (another CPU or MuJoCo version
may round differently, and then the digests are re-taken from a known-good checkout)."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable

import numpy as np
import pytest

from rcbht_introspection.io.trial import Trial
from rcbht_introspection.sim import (
    load_peg_config,
    load_sim_config,
    simulate_peg_trial,
    simulate_trial,
)

CASES: dict[str, tuple[Callable[[], Trial], str]] = {
    "snap one-arm success": (
        lambda: simulate_trial(load_sim_config(), 11),
        "7cfa0d583fa9077b82853d5cf31771b81e6e28380f5400039964f25cdc2532b7",
    ),
    "snap two-arm misalignment": (
        lambda: simulate_trial(load_sim_config(), 5, scenario="two-arm", failure="misalignment"),
        "85462b3b76e9b3c1a33ce68b442f0a142fab75e6c93d86a9ebe875c8d0318659",
    ),
    "snap deviation with onset": (
        lambda: simulate_trial(load_sim_config(), 7, failure="deviation_x+"),
        "1c0c9fea4d486b6f3339ca62659f466e77684cb507e01b2f09d36dab76acbdbe",
    ),
    "peg success": (
        lambda: simulate_peg_trial(load_peg_config(), 3),
        "f832bf0f79e0ef671f1c90b1031928b6300a6d5f6180e224d5a2de8cc505723d",
    ),
    "peg hole_yaw": (
        lambda: simulate_peg_trial(load_peg_config(), 31, failure="hole_yaw"),
        "38359f7035bd5985252fa85a3a2954548dcbcff9ed2d0cf16ffebbf97cdeda4a",
    ),
}


def trial_digest(trial: Trial) -> str:
    """sha256 of a trial's wrench (every arm), sample times, switch times, outcome and metadata."""
    h = hashlib.sha256()
    for arm in sorted(trial.wrench):
        h.update(arm.encode())
        h.update(np.ascontiguousarray(trial.wrench[arm], dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(trial.time, dtype=np.float64).tobytes())
    record = [trial.name, list(trial.state_times), trial.outcome, list(trial.phases)]
    h.update(json.dumps([*record, trial.metadata], sort_keys=True).encode())
    return h.hexdigest()


@pytest.mark.parametrize("case", sorted(CASES))
def test_seeded_trial_is_bit_identical(case: str) -> None:
    simulate, expected = CASES[case]
    assert trial_digest(simulate()) == expected

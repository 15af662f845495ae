"""The real Baxter bags: a verifier trained on one day (session_a) raises no alarm on the
successes of the four other days, as imported and with their force sensor re-biased by +-20 N
on Fz (a sensor re-zeroed between days), with every signal."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from conftest import HIRO, require

from rcbht_introspection.cli import main
from rcbht_introspection.io.bags import read_trial_bag
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.verify.config import VERIFIER_SIGNALS, load_verify_config
from rcbht_introspection.verify.detector import Detector
from rcbht_introspection.verify.features import trial_features

pytestmark = [pytest.mark.shared_data, pytest.mark.slow]

BAXTER = HIRO.parent / "baxter_pick_and_place"
PHASE_MAP = "0=-,1=approach,2=grasp,5=lift,3=transport,4=place"
FZ = 2


def _import(bags: list[Path], out: Path) -> list[Trial]:
    topics = ["--wrench", "/tag_multimodal.wrench_stamped", "--phase", "/tag_multimodal.tag"]
    args = ["bag", "import", *map(str, bags), "--out", str(out), *topics, "--phase-map", PHASE_MAP]
    assert main(args) == 0
    return [read_trial_bag(p) for p in sorted(out.glob("*.mcap"))]


def _rebiased(trial: Trial, fz: float) -> Trial:
    wrench = {arm: np.asarray(w, dtype=float).copy() for arm, w in trial.wrench.items()}
    for w in wrench.values():
        w[:, FZ] += fz
    return dataclasses.replace(trial, name=f"{trial.name}{fz:+g}", wrench=wrench)


def test_other_days_raise_no_alarm_as_imported_and_rebiased(tmp_path: Path) -> None:
    require(BAXTER.is_dir(), f"Baxter bags not found at {BAXTER}")
    day = _import(sorted(BAXTER.glob("session_a/*.bag")), tmp_path / "day")
    others = _import(sorted(BAXTER.glob("other_sessions/*.bag")), tmp_path / "others")
    assert len(day) == 15 and len(others) == 4
    config = load_verify_config()
    signals = VERIFIER_SIGNALS  # every signal, transient and departure included
    detector = Detector.fit([trial_features(t, config) for t in day], config, signals)
    assert detector.signals == signals
    runs = [t for o in others for t in (o, _rebiased(o, 20.0), _rebiased(o, -20.0))]
    alarms = {t.name: detector.run(trial_features(t, config)).alarm for t in runs}
    assert all(a is None for a in alarms.values()), alarms

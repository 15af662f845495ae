"""Does one side of a change call the same motion what the other side calls it?

Every trial is cut into WINDOW_S windows of its wrench (tared at its free-motion level, so a
session's offset does not count), each described by the mean, spread and change of every axis
and labelled with the sub-task it lies in. At a change found in the durations, a random forest
trained on the windows of the trials before it labels the windows after it, and one trained
after labels those before. Where the labels mean the same on both sides, each model mostly gives
the labels the windows carry; after a change of convention it gives the other side's name for
that motion: the share of a sub-task's time called by each name is the evidence shown beside the
change (not a test: the durations decide what is reported).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rcbht_introspection.io.trial import Trial

WINDOW_S = 0.25
"""Length of a classified window (s)."""
MIN_WINDOW_SAMPLES = 3
TREES = 100


def window_features(
    trial: Trial, level: dict[str, tuple[float, ...]]
) -> tuple[np.ndarray, tuple[str, ...]]:
    """((windows, features) float32, sub-task of each window) of a trial's whole sub-tasks."""
    tared = (
        np.hstack([trial.wrench[arm] - np.asarray(level[arm]) for arm in trial.arms])
        if trial.arms
        else np.zeros((len(trial.time), 0))
    )
    rows: list[np.ndarray] = []
    labels: list[str] = []
    time = np.asarray(trial.time, dtype=np.float64)
    for name, start, end in trial.subtask_bounds():
        edges = np.arange(start, end - WINDOW_S + 1e-9, WINDOW_S)
        lo = np.searchsorted(time, edges)
        hi = np.searchsorted(time, edges + WINDOW_S)
        for a, b in zip(lo.tolist(), hi.tolist(), strict=True):
            if b - a < MIN_WINDOW_SAMPLES:
                continue
            seg = tared[a:b]
            rows.append(np.concatenate([seg.mean(axis=0), seg.std(axis=0), seg[-1] - seg[0]]))
            labels.append(name)
    width = 3 * tared.shape[1]
    features = np.asarray(rows, dtype=np.float32).reshape(len(rows), width)
    return features, tuple(labels)


@dataclass(frozen=True)
class Agreement:
    """Per true label of one side, the share of its windows the other side's model calls each
    label; and how many windows each side had."""

    after_by_before: dict[str, dict[str, float]]
    """Sub-task of a window after the change -> {name the model of the trials before gives: share}."""
    before_by_after: dict[str, dict[str, float]]
    windows: tuple[int, int]

    def to_dict(self) -> dict[str, object]:
        return {
            "after_called_by_model_before": self.after_by_before,
            "before_called_by_model_after": self.before_by_after,
            "windows": list(self.windows),
            "window_s": WINDOW_S,
        }


def _stack(
    windows: Sequence[tuple[np.ndarray, tuple[str, ...]]],
) -> tuple[np.ndarray, np.ndarray]:
    widths = {w.shape[1] for w, _ in windows}
    if len(widths) != 1:
        return np.zeros((0, 0), dtype=np.float32), np.array([], dtype=str)
    x = np.vstack([w for w, _ in windows])
    y = np.array([label for _, labels in windows for label in labels], dtype=str)
    return x, y


def _called(
    model_x: np.ndarray, model_y: np.ndarray, x: np.ndarray, y: np.ndarray, seed: int
) -> dict[str, dict[str, float]]:
    from sklearn.ensemble import RandomForestClassifier

    model = RandomForestClassifier(n_estimators=TREES, random_state=seed, n_jobs=1)
    predicted = model.fit(model_x, model_y).predict(x)
    out: dict[str, dict[str, float]] = {}
    for label in sorted(set(y.tolist())):
        mine = predicted[y == label]
        names, counts = np.unique(mine, return_counts=True)
        order = np.argsort(-counts, kind="stable")
        out[label] = {str(names[i]): round(float(counts[i]) / len(mine), 4) for i in order}
    return out


def cross_agreement(
    before: Sequence[tuple[np.ndarray, tuple[str, ...]]],
    after: Sequence[tuple[np.ndarray, tuple[str, ...]]],
    seed: int,
) -> Agreement | None:
    """Each side's windows as the other side's model labels them (None: too few windows, one
    label only on a side, or trials of different arms)."""
    xb, yb = _stack(before)
    xa, ya = _stack(after)
    if min(len(xb), len(xa)) == 0 or xb.shape[1] != xa.shape[1]:
        return None
    if len(set(yb.tolist())) < 2 or len(set(ya.tolist())) < 2:
        return None
    return Agreement(
        _called(xb, yb, xa, ya, seed), _called(xa, ya, xb, yb, seed), (len(xb), len(xa))
    )

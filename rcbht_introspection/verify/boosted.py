"""Gradient-boosted trees for the characteriser's heads, as plain arrays.

scikit-learn's HistGradientBoostingClassifier learns the trees; they are then packed into flat
node arrays, which a verifier file stores without pickling (loading executes no code) and which
predict one evidence row in a few vectorised steps instead of the estimator's per-call set-up
of tens of milliseconds. `predict_proba` equals the scikit-learn model's (tested).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.ensemble import HistGradientBoostingClassifier

ARRAYS = ("feature", "threshold", "left", "right", "leaf", "value", "roots", "baseline")
"""The packed model's arrays (left/right are global node indices; leaf marks leaves)."""


class BoostedTrees(ClassifierMixin, BaseEstimator):
    """A boosted-trees classifier (scikit-learn conventions) whose fitted state is plain arrays."""

    def __init__(
        self,
        max_iter: int = 100,
        learning_rate: float = 0.1,
        max_leaf_nodes: int = 15,
        random_state: int = 0,
    ) -> None:
        self.max_iter = max_iter
        self.learning_rate = learning_rate
        self.max_leaf_nodes = max_leaf_nodes
        self.random_state = random_state

    def fit(self, X: np.ndarray, y: Sequence[str]) -> BoostedTrees:
        """Learn with scikit-learn, then keep only the packed trees."""
        model = HistGradientBoostingClassifier(
            max_iter=self.max_iter,
            learning_rate=self.learning_rate,
            max_leaf_nodes=self.max_leaf_nodes,
            early_stopping=False,
            random_state=self.random_state,
        ).fit(np.asarray(X, dtype=float), np.asarray(y, dtype=str))
        self.classes_ = np.asarray(model.classes_, dtype=str)
        self.n_features_in_ = int(model.n_features_in_)
        self.arrays_ = pack(model)
        return self

    def raw(self, X: np.ndarray) -> np.ndarray:
        """(rows, trees per iteration) summed leaf values plus the baseline."""
        a = self.arrays_
        X = np.asarray(X, dtype=float)
        node = np.broadcast_to(a["roots"], (len(X), len(a["roots"]))).copy()
        rows = np.arange(len(X))[:, None]
        while True:
            inner = ~a["leaf"][node]
            if not inner.any():
                break
            go_left = X[rows, a["feature"][node]] <= a["threshold"][node]
            step = np.where(go_left, a["left"][node], a["right"][node])
            node = np.where(inner, step, node)
        per_iteration = len(a["baseline"])
        values = a["value"][node].reshape(len(X), -1, per_iteration)
        return values.sum(axis=1) + a["baseline"]

    def predict_proba(self, X: np.ndarray) -> np.ndarray:
        raw = self.raw(X)
        if raw.shape[1] == 1:  # two classes: one tree per iteration, the logistic link
            p = 1.0 / (1.0 + np.exp(-raw[:, 0]))
            return np.column_stack([1.0 - p, p])
        e = np.exp(raw - raw.max(axis=1, keepdims=True))
        return e / e.sum(axis=1, keepdims=True)

    def predict(self, X: np.ndarray) -> np.ndarray:
        return self.classes_[np.argmax(self.predict_proba(X), axis=1)]

    @classmethod
    def from_arrays(
        cls, params: dict[str, Any], classes: Sequence[str], arrays: dict[str, np.ndarray]
    ) -> BoostedTrees:
        """A fitted model from its packed arrays (a verifier file); inconsistent ones raise."""
        model = cls(**params)
        model.classes_ = np.asarray(classes, dtype=str)
        model.arrays_ = {k: np.asarray(arrays[k]) for k in ARRAYS}
        model.n_features_in_ = int(arrays["n_features"])
        check_packed(model.arrays_, len(model.classes_), model.n_features_in_)
        return model


def pack(model: HistGradientBoostingClassifier) -> dict[str, np.ndarray]:
    """Flat node arrays of a fitted model's trees, iteration by iteration."""
    trees = [p for iteration in model._predictors for p in iteration]
    if any(bool(t.nodes["is_categorical"].any()) for t in trees):
        raise ValueError("categorical splits are not packed")
    offsets = np.cumsum([0] + [len(t.nodes) for t in trees])
    nodes = np.concatenate([t.nodes for t in trees])
    shift = np.repeat(offsets[:-1], [len(t.nodes) for t in trees])
    return {
        "feature": nodes["feature_idx"].astype(np.int64),
        "threshold": nodes["num_threshold"].astype(float),
        "left": (nodes["left"].astype(np.int64) + shift),
        "right": (nodes["right"].astype(np.int64) + shift),
        "leaf": nodes["is_leaf"].astype(bool),
        "value": nodes["value"].astype(float),
        "roots": offsets[:-1].astype(np.int64),
        "baseline": np.asarray(model._baseline_prediction, dtype=float).ravel(),
    }


def check_packed(a: dict[str, np.ndarray], n_classes: int, n_features: int) -> None:
    """Packed arrays that form trees over `n_features` features (else ValueError)."""
    n = len(a["leaf"])
    if any(len(a[k]) != n for k in ("feature", "threshold", "left", "right", "value")):
        raise ValueError("packed node arrays differ in length")
    inner = ~a["leaf"]
    for k in ("left", "right"):
        child = a[k][inner]
        if np.any(child <= np.flatnonzero(inner)) or np.any(child >= n):
            raise ValueError(f"packed trees' {k} children do not point forward")
    if np.any((a["feature"][inner] < 0) | (a["feature"][inner] >= n_features)):
        raise ValueError("packed trees split on features the model does not read")
    if np.any((a["roots"] < 0) | (a["roots"] >= max(n, 1))):
        raise ValueError("packed tree roots lie outside the nodes")
    per_iteration = len(a["baseline"])
    if per_iteration != (1 if n_classes == 2 else n_classes) or len(a["roots"]) % per_iteration:
        raise ValueError("packed trees do not match the classes")

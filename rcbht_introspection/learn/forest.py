"""Random forests as plain arrays: the characteriser's heads and the sub-task vote's forest.

scikit-learn's RandomForestClassifier learns the trees; they are then packed into flat node
arrays, which a verifier file stores without pickling (loading executes no code) and which
predict one evidence row in a few vectorised steps instead of the estimator's per-call set-up.
`predict_proba` equals the scikit-learn model's (tested).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.ensemble import RandomForestClassifier
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_is_fitted, validate_data

ARRAYS = ("feature", "threshold", "left", "right", "leaf", "value", "roots")
"""The packed model's arrays: per node its split (feature, threshold), its children as global
node indices, whether it is a leaf and, for leaves, the class shares (others: zeros)."""


class ForestHead(ClassifierMixin, BaseEstimator):  # type: ignore[misc]
    """A random-forest classifier (scikit-learn conventions) whose fitted state is plain arrays."""

    def __init__(
        self,
        n_estimators: int = 100,
        min_samples_leaf: int = 2,
        max_features: str = "sqrt",
        random_state: int = 0,
    ) -> None:
        self.n_estimators = n_estimators
        self.min_samples_leaf = min_samples_leaf
        self.max_features = max_features
        self.random_state = random_state

    def fit(self, X: np.ndarray, y: Sequence[Any] | np.ndarray) -> ForestHead:
        """Learn with scikit-learn (one process), then keep only the packed trees."""
        X, y = validate_data(self, X, y)
        check_classification_targets(y)
        model = RandomForestClassifier(
            n_estimators=self.n_estimators,
            min_samples_leaf=self.min_samples_leaf,
            max_features=self.max_features,
            random_state=self.random_state,
        ).fit(X, y)
        self.classes_ = np.asarray(model.classes_)
        self.arrays_ = pack(model)
        return self

    def predict_proba(self, X: np.ndarray) -> np.ndarray:
        """The trees' mean class shares at the rows' leaves."""
        check_is_fitted(self, "arrays_")
        return self.shares(validate_data(self, X, reset=False))

    def shares(self, X: np.ndarray) -> np.ndarray:
        """predict_proba without scikit-learn's input checks, for rows the caller built of the
        fitted width (the live path's one row a tick; rows compared as float32, as
        scikit-learn's trees compare them)."""
        a = self.arrays_
        X = np.asarray(X, dtype=np.float32)
        node = np.broadcast_to(a["roots"], (len(X), len(a["roots"]))).copy()
        rows = np.arange(len(X))[:, None]
        while True:
            inner = ~a["leaf"][node]
            if not inner.any():
                break
            go_left = X[rows, a["feature"][node]] <= a["threshold"][node]
            node = np.where(inner, np.where(go_left, a["left"][node], a["right"][node]), node)
        return np.asarray(a["value"][node].mean(axis=1), dtype=float)

    def predict(self, X: np.ndarray) -> np.ndarray:
        check_is_fitted(self, "arrays_")
        predicted: np.ndarray = self.classes_[np.argmax(self.predict_proba(X), axis=1)]
        return predicted

    @classmethod
    def from_arrays(
        cls, params: dict[str, Any], classes: Sequence[str], arrays: dict[str, np.ndarray]
    ) -> ForestHead:
        """A fitted model from its packed arrays (a verifier file); inconsistent ones raise."""
        model = cls(**params)
        model.classes_ = np.asarray(classes, dtype=str)
        model.arrays_ = {k: np.asarray(arrays[k]) for k in ARRAYS}
        model.n_features_in_ = int(arrays["n_features"])
        check_packed(model.arrays_, len(model.classes_), model.n_features_in_)
        return model


def pack(model: RandomForestClassifier) -> dict[str, np.ndarray]:
    """Flat node arrays of a fitted forest's trees, tree after tree."""
    trees = [e.tree_ for e in model.estimators_]
    sizes = [t.node_count for t in trees]
    shift = np.repeat(np.cumsum([0, *sizes[:-1]]), sizes)
    leaf = np.concatenate([t.children_left == -1 for t in trees])
    value = np.concatenate([t.value[:, 0, :] for t in trees]).astype(np.float32)
    value /= np.maximum(value.sum(axis=1, keepdims=True), 1e-12)
    value[~leaf] = 0.0  # never read: zeros pack small
    left = np.concatenate([t.children_left for t in trees]).astype(np.int64) + shift
    right = np.concatenate([t.children_right for t in trees]).astype(np.int64) + shift
    return {
        "feature": np.where(leaf, 0, np.concatenate([t.feature for t in trees])).astype(np.int32),
        "threshold": np.concatenate([t.threshold for t in trees]).astype(float),
        "left": np.where(leaf, 0, left),
        "right": np.where(leaf, 0, right),
        "leaf": leaf,
        "value": value,
        "roots": np.cumsum([0, *sizes[:-1]]).astype(np.int64),
    }


def check_packed(a: dict[str, np.ndarray], n_classes: int, n_features: int) -> None:
    """Packed arrays that form trees over `n_features` features (else ValueError)."""
    n = len(a["leaf"])
    if any(len(a[k]) != n for k in ("feature", "threshold", "left", "right", "value")):
        raise ValueError("packed node arrays differ in length")
    if a["value"].ndim != 2 or a["value"].shape[1] != n_classes:
        raise ValueError("packed trees do not match the classes")
    inner = ~a["leaf"].astype(bool)
    for k in ("left", "right"):
        child = a[k][inner]
        if np.any(child <= np.flatnonzero(inner)) or np.any(child >= n):
            raise ValueError(f"packed trees' {k} children do not point forward")
    if np.any((a["feature"][inner] < 0) | (a["feature"][inner] >= n_features)):
        raise ValueError("packed trees split on features the model does not read")
    if len(a["roots"]) == 0 or np.any((a["roots"] < 0) | (a["roots"] >= max(n, 1))):
        raise ValueError("packed tree roots lie outside the nodes")

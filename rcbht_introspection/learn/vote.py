"""The paper's SVM and a random forest, their probabilities averaged: the words + wrench default.

The SVM (standardised features, RBF) reads the word counts well within one set of recordings;
the forest's axis-aligned splits keep a wrench feature that moved on another day from dragging a
whole distance. Their mean probability held up on both (docs/results-learning.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from sklearn.base import BaseEstimator, ClassifierMixin

from rcbht_introspection.learn.forest import ForestHead
from rcbht_introspection.learn.svm import fit_svm, make_svm, svm_predict_proba


class SvmForestClassifier(ClassifierMixin, BaseEstimator):  # type: ignore[misc]
    """Soft vote of the paper's SVM pipeline and a packed random forest (scikit-learn conventions)."""

    def __init__(self, n_estimators: int = 100, random_state: int = 0) -> None:
        self.n_estimators = n_estimators
        self.random_state = random_state

    def fit(self, X: NDArray[np.float64], y: Sequence[str]) -> SvmForestClassifier:
        """Fit both members on the same rows."""
        labels = [str(label) for label in y]
        self.svm_ = fit_svm(make_svm(self.random_state), X, labels)
        self.forest_ = ForestHead(
            n_estimators=self.n_estimators, min_samples_leaf=1, random_state=self.random_state
        ).fit(X, labels)
        return self._check()

    def _check(self) -> SvmForestClassifier:
        svm_classes = [str(c) for c in self.svm_.classes_]
        if svm_classes != [str(c) for c in self.forest_.classes_]:
            raise ValueError("the SVM and the forest name different classes")
        self.classes_ = np.asarray(svm_classes, dtype=str)
        self.n_features_in_ = int(self.forest_.n_features_in_)
        return self

    def predict_proba(self, X: NDArray[np.float64]) -> NDArray[np.float64]:
        """The mean of the members' class probabilities (columns in classes_ order)."""
        proba: NDArray[np.float64] = 0.5 * (
            svm_predict_proba(self.svm_, X) + self.forest_.predict_proba(X)
        )
        return proba

    def predict(self, X: NDArray[np.float64]) -> NDArray[np.str_]:
        """The class of the highest mean probability."""
        predicted: NDArray[np.str_] = self.classes_[np.argmax(self.predict_proba(X), axis=1)]
        return predicted

    @classmethod
    def from_members(
        cls, svm: Any, forest: ForestHead, params: dict[str, Any]
    ) -> SvmForestClassifier:
        """A fitted vote from its stored members (a model file)."""
        model = cls(**params)
        model.svm_, model.forest_ = svm, forest
        return model._check()

"""The paper's sub-task classifier: standardised features and an RBF SVC with Platt probabilities.

Also its tuned variant (svm-tuned: C and gamma by trial-grouped CV on the training data) and a
fast, bit-identical predict_proba for the live path.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from sklearn.model_selection import GroupKFold, cross_val_score
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVC

TUNING_GRID: dict[str, list[float]] = {
    "C": [0.1, 1.0, 10.0, 100.0],
    "gamma_factor": [0.1, 1.0, 10.0],
}
"""svm-tuned: C and a multiple of the 'scale' gamma, chosen by trial-grouped CV on training data."""


def make_svm(random_state: int = 0) -> Pipeline:
    """The paper's classifier: standardised features, RBF SVC, C=1, one-vs-one, Platt probabilities."""
    return Pipeline(
        [
            ("scale", StandardScaler()),
            (
                "svc",
                SVC(
                    kernel="rbf",
                    C=1.0,
                    decision_function_shape="ovo",
                    probability=True,
                    random_state=random_state,
                ),
            ),
        ]
    )


def _checked_predict_proba(estimator: Any, X: np.ndarray) -> NDArray[np.float64]:
    """estimator.predict_proba(X) as sklearn runs it, input checks included."""
    proba: NDArray[np.float64] = estimator.predict_proba(X)
    return proba


def svm_predict_proba(estimator: Any, X: np.ndarray) -> np.ndarray:
    """estimator.predict_proba(X), without sklearn's per-call input checks for our SVM pipeline.

    Those checks cost ~0.5 ms per live window; the arithmetic is the pipeline's own
    (StandardScaler's in-place centring and scaling, then SVC's libsvm call), so the result is
    identical. Any other estimator, or input the checks would reject, takes the checked path.
    """
    if not isinstance(estimator, Pipeline):
        return _checked_predict_proba(estimator, X)
    steps = estimator.steps
    if len(steps) != 2 or type(steps[0][1]) is not StandardScaler or type(steps[1][1]) is not SVC:
        return _checked_predict_proba(estimator, X)
    scaler, svc = steps[0][1], steps[1][1]
    if (
        not isinstance(X, np.ndarray)
        or X.ndim != 2
        or X.dtype != np.float64
        or X.shape[1] != getattr(scaler, "n_features_in_", -1)
        or getattr(svc, "_sparse", True)
        or svc.kernel not in ("rbf", "linear", "poly", "sigmoid")
        or getattr(svc, "_probA", np.empty(0)).size == 0
        or svc.n_support_.sum() != svc.support_vectors_.shape[0]
        or not np.isfinite(X).all()
    ):
        return _checked_predict_proba(estimator, X)
    Xt = np.array(X, dtype=np.float64, order="C", copy=True)
    if scaler.with_mean:
        Xt -= scaler.mean_
    if scaler.with_std:
        Xt /= scaler.scale_
    proba: NDArray[np.float64] = svc._dense_predict_proba(Xt)
    return proba


def fit_svm(estimator: Pipeline, X: np.ndarray, y: Sequence[str]) -> Pipeline:
    """Fit, silencing only sklearn 1.9's deprecation of SVC(probability=True) (the paper's setting)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*probability.*", category=FutureWarning)
        return estimator.fit(X, list(y))


def tune_svm(
    X: np.ndarray, y: Sequence[str], groups: Sequence[str], random_state: int = 0
) -> dict[str, Any]:
    """Inner, trial-grouped 3-fold CV over TUNING_GRID on the training data only.

    Returns pipeline parameters (svc__C, svc__gamma); the paper's C=1, gamma='scale' when there
    are fewer than 3 training trials to cross-validate over.
    """

    if len(set(groups)) < 3:
        return {"svc__C": 1.0, "svc__gamma": "scale"}
    scaled = StandardScaler().fit_transform(X)
    scale_gamma = 1.0 / (X.shape[1] * max(float(scaled.var()), 1e-12))
    best, best_score = {"svc__C": 1.0, "svc__gamma": "scale"}, -1.0
    for c in TUNING_GRID["C"]:
        for factor in TUNING_GRID["gamma_factor"]:
            candidate = Pipeline(
                [("scale", StandardScaler()), ("svc", SVC(C=c, gamma=factor * scale_gamma))]
            )
            score = cross_val_score(
                candidate, X, list(y), groups=list(groups), cv=GroupKFold(3)
            ).mean()
            if score > best_score + 1e-12:
                best, best_score = {"svc__C": c, "svc__gamma": factor * scale_gamma}, score
    return best


__all__ = ["TUNING_GRID", "fit_svm", "make_svm", "svm_predict_proba", "tune_svm"]

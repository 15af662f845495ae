"""MiniRocket (aeon) with a ridge classifier: the stock time-series classifier of the failure class.

As a stock user would run it: each evidence window (T_i, d) is resampled by linear
interpolation along time to `n_points`, transformed by aeon's multivariate MiniRocket
(`aeon.transformations.collection.convolution_based.MiniRocket`, 10,000 kernels, input
(n_cases, n_channels, n_timepoints)), standardised (StandardScaler) and classified by
RidgeClassifierCV(alphas=logspace(-3, 3, 10)) (Dempster, Schmidt, Webb, KDD 2021).

Detection: this module offers none, so the minirocket column has no detector. MiniRocket is a
transform for supervised classification; the one-class variant of the family that aeon 1.6
ships, ROCKAD (Theissler et al., IDA 2023: ROCKET features, Yeo-Johnson, bagged k-NN
distances, trained on normal series only), is sound for whole series but scores a finished
series (aeon.anomaly_detection.collection.ROCKAD) or fixed sliding windows of one series
(aeon.anomaly_detection.series.distance_based.ROCKAD), with ROCKET rather than MiniRocket
kernels. A per-tick alarm from it would be another method (windows, a window length, a
neighbour count to choose), not MiniRocket's own.

aeon's kernels are compiled by numba on first use (about 20 s on 2 cores) and cached on disk
(numba's cache: beside aeon's sources, or NUMBA_CACHE_DIR); later processes load them in
well under a second.
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.linear_model import RidgeClassifierCV
from sklearn.preprocessing import StandardScaler

from rcbht_introspection.summaries.windows import to_panel

MIN_POINTS = 9
"""MiniRocket's kernels are 9 long: a series must have at least 9 time points."""
RIDGE_ALPHAS = np.logspace(-3, 3, 10)


# sklearn has no type hints, so its bases are Any: strict mypy refuses to subclass them
class MiniRocketClassifier(ClassifierMixin, BaseEstimator):  # type: ignore[misc]
    """Resample to n_points, MiniRocket (multivariate), StandardScaler, RidgeClassifierCV.

    No predict_proba (a ridge classifier has none); `decision_function` gives the ridge
    scores per class.
    """

    def __init__(self, n_points: int = 150, random_state: int | None = 0) -> None:
        self.n_points = n_points
        self.random_state = random_state

    def fit(self, windows: Sequence[np.ndarray], y: Sequence[object]) -> MiniRocketClassifier:
        """Fit the transform's dilations and biases, the scaler and the ridge classifier."""
        from aeon.transformations.collection.convolution_based import MiniRocket

        n = self.n_points
        if not isinstance(n, numbers.Integral) or isinstance(n, bool) or n < MIN_POINTS:
            raise ValueError(f"n_points must be an integer >= {MIN_POINTS}, got {n!r}")
        labels = np.asarray(y)
        if len(windows) != len(labels):
            raise ValueError(f"{len(windows)} windows but {len(labels)} labels")
        panel = to_panel(windows, n)
        self.transform_: Any = MiniRocket(random_state=self.random_state).fit(panel)
        features = self.transform_.transform(panel)
        self.scaler_: Any = StandardScaler().fit(features)
        self.ridge_: Any = RidgeClassifierCV(alphas=RIDGE_ALPHAS).fit(
            self.scaler_.transform(features), labels
        )
        self.classes_ = self.ridge_.classes_
        return self

    def _features(self, windows: Sequence[np.ndarray]) -> np.ndarray:
        features = self.transform_.transform(to_panel(windows, self.n_points))
        return np.asarray(self.scaler_.transform(features))

    def decision_function(self, windows: Sequence[np.ndarray]) -> np.ndarray:
        """Ridge scores: (n,) for two classes (positive = classes_[1]), else (n, n_classes)."""
        return np.asarray(self.ridge_.decision_function(self._features(windows)))

    def predict(self, windows: Sequence[np.ndarray]) -> np.ndarray:
        """The class with the highest ridge score per window."""
        return np.asarray(self.ridge_.predict(self._features(windows)))

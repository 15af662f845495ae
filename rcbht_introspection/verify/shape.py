"""The characteriser's shape head: how the evidence moved since onset, read by MiniRocket.

The span summaries (verify/characterise.py) see the evidence as a few means; this head sees its
shape. The window is the view's vectors of the ticks since onset minus the reference (sensor
bias and gripper load cancel), resampled along time to `n_points`, transformed by aeon's
multivariate MiniRocket (Dempster, Schmidt, Webb, KDD 2021), standardised and classified by a
multinomial logistic regression. `vote_weight` learns how much it counts beside the forest from
the training failures: held-out log-loss over trial-grouped folds, a weight of the grid
WEIGHTS, 0 when the forest alone does best. Its fitted state is plain arrays (the safe file):
MiniRocket's parameters, the scaler's moments and the logistic coefficients, set back into
aeon's MiniRocket and scikit-learn's LogisticRegression when a file is read.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.linear_model import LogisticRegression
from sklearn.model_selection import GroupKFold
from sklearn.preprocessing import StandardScaler

from rcbht_introspection.summaries.windows import to_panel

WEIGHTS = (0.0, 0.25, 0.5, 0.75, 1.0)
"""The shape head's vote weights tried (the forest has 1 - weight)."""
FOLDS = 3
"""Trial-grouped folds of the training failures that choose the weight."""
CLIP = 1e6
"""Evidence values are clipped here, the span summaries' and the windows' (an overflowing sensor
must not give inf or NaN)."""
FLAT = "Data seen by instance of MiniRocket has one or more case/channel pairs"
"""aeon's warning for a channel that barely varies: expected of a short window (a tick or two
since onset, resampled), so not printed."""
PARAMETERS = ("channels_per_combination", "channel_indices", "dilations", "per_dilation", "biases")
"""MiniRocket's fitted parameters (aeon's `parameters` tuple, in its order)."""


class ShapeHead(BaseEstimator):  # type: ignore[misc]
    """Evidence windows (ticks, channels) -> class probabilities."""

    def __init__(
        self, n_kernels: int = 2000, n_points: int = 64, C: float = 0.01, random_state: int = 0
    ) -> None:
        self.n_kernels = n_kernels
        self.n_points = n_points
        self.C = C
        self.random_state = random_state

    def fit(self, windows: Sequence[np.ndarray], y: Sequence[str]) -> ShapeHead:
        """MiniRocket's dilations and biases, the scaler and the logistic regression."""
        from aeon.transformations.collection.convolution_based import MiniRocket

        panel = self._panel(windows)
        self.transform_: Any = MiniRocket(
            n_kernels=self.n_kernels, n_jobs=1, random_state=self.random_state
        )
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=FLAT)
            features = self.transform_.fit(panel).transform(panel)
        scaler = StandardScaler().fit(features)
        self.mean_, self.scale_ = scaler.mean_, scaler.scale_
        self.logistic_ = LogisticRegression(C=self.C, max_iter=300).fit(
            scaler.transform(features), [str(c) for c in y]
        )
        self.classes_ = np.asarray(self.logistic_.classes_, dtype=str)
        self.n_channels_ = int(panel.shape[1])
        return self

    def _panel(self, windows: Sequence[np.ndarray]) -> np.ndarray:
        return to_panel([np.clip(np.nan_to_num(w), -CLIP, CLIP) for w in windows], self.n_points)

    def predict_proba(self, windows: Sequence[np.ndarray]) -> np.ndarray:
        """(n, classes) probabilities of the logistic regression, columns in classes_ order."""
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=FLAT)
            features = self.transform_.transform(self._panel(windows))
        proba: np.ndarray = self.logistic_.predict_proba((features - self.mean_) / self.scale_)
        return proba

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The fitted state as plain arrays."""
        params = dict(zip(PARAMETERS, self.transform_.parameters, strict=True))
        return {
            **params,
            "mean": self.mean_,
            "scale": self.scale_,
            "coef": self.logistic_.coef_,
            "intercept": self.logistic_.intercept_,
            "n_channels": np.array(self.n_channels_),
        }

    @classmethod
    def from_arrays(
        cls, params: dict[str, Any], classes: Sequence[str], arrays: dict[str, np.ndarray]
    ) -> ShapeHead:
        """A head from `to_arrays` (no code runs: aeon's MiniRocket gets the parameters back)."""
        from aeon.transformations.collection.convolution_based import MiniRocket

        head = cls(**params)
        kinds = (np.int32, np.int32, np.int32, np.int32, np.float32)
        n_channels = int(arrays["n_channels"])
        mr = MiniRocket(n_kernels=head.n_kernels, n_jobs=1, random_state=head.random_state)
        # aeon's public fit sets its fitted state; the kernels' parameters are then the file's
        mr.fit(np.zeros((2, n_channels, head.n_points), dtype=np.float32))
        mr.parameters = tuple(
            np.asarray(arrays[k], dtype=t) for k, t in zip(PARAMETERS, kinds, strict=True)
        )
        head.transform_ = mr
        head.mean_, head.scale_ = np.asarray(arrays["mean"]), np.asarray(arrays["scale"])
        coef, intercept = np.asarray(arrays["coef"]), np.asarray(arrays["intercept"])
        head.classes_ = np.asarray(classes, dtype=str)
        head.n_channels_ = n_channels
        n = len(head.mean_)
        if head.scale_.shape != (n,) or coef.shape[1:] != (n,):
            raise ValueError("the shape head's arrays do not match its features")
        rows = 1 if len(head.classes_) == 2 else len(head.classes_)
        if coef.shape[0] != rows or intercept.shape != (rows,):
            raise ValueError("the shape head's coefficients do not match its classes")
        logistic = LogisticRegression(C=head.C, max_iter=300)  # the fitted state, set back
        logistic.coef_, logistic.intercept_, logistic.classes_ = coef, intercept, head.classes_
        logistic.n_features_in_ = n
        head.logistic_ = logistic
        return head


def mix(
    forest: dict[str, float], shape: np.ndarray, classes: np.ndarray, weight: float
) -> dict[str, float]:
    """The vote: (1 - weight) * the forest's probability + weight * the shape head's."""
    named = {str(c): float(p) for c, p in zip(classes, shape, strict=True)}
    return {c: (1.0 - weight) * p + weight * named.get(c, 0.0) for c, p in forest.items()}


def vote_weight(
    forest: Callable[[], Any],
    head: ShapeHead,
    X: np.ndarray,
    windows: Sequence[np.ndarray],
    y: Sequence[str],
    groups: Sequence[str],
) -> float:
    """The weight of WEIGHTS whose vote has the least log-loss on rows held out by trial
    (`forest()`: a new forest head; `head`: the shape head's settings)."""
    keys = np.asarray(groups)
    if len(set(keys)) < FOLDS or len(set(y)) < 2:
        return 0.0
    classes = sorted(set(y))
    labels = np.asarray(y)
    held = np.zeros((2, len(y), len(classes)))
    for train, test in GroupKFold(n_splits=FOLDS).split(X, labels, keys):
        if len(set(labels[train])) < 2:
            return 0.0
        f = forest().fit(X[train], list(labels[train]))
        s = ShapeHead(**head.get_params()).fit([windows[i] for i in train], labels[train])
        for k, (model, proba) in enumerate(
            ((f, f.predict_proba(X[test])), (s, s.predict_proba([windows[i] for i in test])))
        ):
            for j, c in enumerate(model.classes_):
                held[k][test, classes.index(str(c))] = proba[:, j]
    truth = np.array([classes.index(c) for c in labels])
    losses = [
        -np.mean(
            np.log(np.clip(((1 - w) * held[0] + w * held[1])[np.arange(len(y)), truth], 1e-6, 1.0))
        )
        for w in WEIGHTS
    ]
    return float(WEIGHTS[int(np.argmin(losses))])

"""The successor framework's HMM anomaly detector and HMM-likelihood classifier (hmmlearn).

Follows birlrobotics/smach_based_introspection_framework (ROS 1), the introspection framework
of the group that published RCBHT:

- one `hmmlearn.hmm.GaussianHMM` per skill (sub-task) on the wrench, trained on successful
  trials only, started in state 0 (`startprob_` fixed to [1, 0, ...], `params="mct"`,
  `init_params="cmt"`, as its model generator does);
- the anomaly test compares the cumulative log-likelihood log p(x_1..x_t) of the running skill
  with the successes' curves at the same step t: an anomaly when it falls below their mean
  minus c standard deviations (its model scoring forms the same lower bound). Here `score`
  returns (mean_t - loglik_t) / std_t, so the caller's threshold on the score is c;
- anomaly kinds are named by the likelihood of one HMM per kind (its
  NormalDistributedConfidenceClassifier: the kind whose model scores the window highest).

Its settings that this module keeps: a Gaussian HMM with 1-9 states (the framework searched
1, 3, 5, 7, 9 by held-out likelihood; 5 here, fixed), up to 1000 EM iterations (hmmlearn stops
earlier at tol=0.01; 100 here), covariance type from a grid ("diag" here), inputs standardised
(its filters scale every channel). It resampled topics to 10 Hz with a 5-sample boxcar; the
caller here feeds window means on its own tick grid.
"""

from __future__ import annotations

import logging
import numbers
from collections.abc import Iterator, Mapping, Sequence
from contextlib import AbstractContextManager, contextmanager
from functools import cache
from typing import Any

import numpy as np
from hmmlearn.hmm import GaussianHMM
from numpy.typing import NDArray
from scipy.linalg import solve_triangular
from scipy.special import softmax
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.preprocessing import StandardScaler
from threadpoolctl import ThreadpoolController

STD_FLOOR = 1e-6
"""Smallest spread of the successes' log-likelihood at a step, relative to max(1, |mean|): one
success (or identical ones) gives a spread of zero."""


@cache
def _controller() -> ThreadpoolController:
    return ThreadpoolController()


def one_thread() -> AbstractContextManager[Any]:
    """BLAS and OpenMP on one thread: on small arrays their threads only spin against each
    other, and on 2 busy cores that costs 15x (k-means: 200 ms instead of 1 ms a run; the
    emission densities: 13 ms instead of 0.9 ms for 400 frames)."""
    limited: AbstractContextManager[Any] = _controller().limit(limits=1)
    return limited


def as_frames(seq: np.ndarray | Sequence[Sequence[float]]) -> np.ndarray:
    """A (T, d) float array; a 1-D sequence is one channel."""
    frames = np.asarray(seq, dtype=np.float64)
    if frames.ndim == 1:
        frames = frames[:, None]
    if frames.ndim != 2:
        raise ValueError(f"a sequence must be (T, d), got shape {frames.shape}")
    return frames


def _check_params(n_components: int, n_iter: int) -> None:
    for name, value in (("n_components", n_components), ("n_iter", n_iter)):
        if not isinstance(value, numbers.Integral) or isinstance(value, bool) or value < 1:
            raise ValueError(f"{name} must be a positive integer, got {value!r}")


@contextmanager
def _quiet_hmmlearn() -> Iterator[None]:
    """hmmlearn logs a line per EM step that does not improve and per state never left (both
    handled here): hundreds of lines in an evaluation's output. Only its errors pass."""
    log = logging.getLogger("hmmlearn")
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        yield
    finally:
        log.setLevel(level)


def fit_hmm(
    frames: Sequence[np.ndarray],
    n_components: int,
    covariance_type: str,
    n_iter: int,
    random_state: int | None,
) -> GaussianHMM:
    """One GaussianHMM on the (already standardised) sequences, started in state 0.

    Fewer frames than states: as many states as frames (k-means needs one frame per state).
    A state never left in the training data (a zero row of transmat_) is made to stay in itself.
    """
    data = np.concatenate(frames)
    states = max(1, min(n_components, len(data)))
    model = GaussianHMM(
        n_components=states,
        covariance_type=covariance_type,
        n_iter=n_iter,
        random_state=random_state,
        params="mct",
        init_params="cmt",
    )
    start = np.zeros(states)
    start[0] = 1.0
    model.startprob_ = start
    with one_thread(), _quiet_hmmlearn():
        model.fit(data, lengths=[len(f) for f in frames])
    # a state seen only at the end of sequences has no observed way out (a zero row, which
    # hmmlearn then refuses to score with): it stays in itself
    trans = model.transmat_.copy()
    stuck = ~np.isclose(trans.sum(axis=1), 1.0)
    trans[stuck] = np.eye(states)[stuck]
    model.transmat_ = trans
    return model


def _emission_loglik(model: GaussianHMM, frames: np.ndarray) -> np.ndarray:
    """log N(x_t | mean_k, cov_k) for every frame and state: (T, K), from the public fields."""
    out = np.empty((len(frames), model.n_components))
    d = frames.shape[1]
    for k, (mean, cov) in enumerate(zip(model.means_, model.covars_, strict=True)):
        chol = np.linalg.cholesky(cov)
        z = solve_triangular(chol, (frames - mean).T, lower=True)
        log_det = 2.0 * np.log(np.diag(chol)).sum()
        out[:, k] = -0.5 * ((z**2).sum(axis=0) + d * np.log(2.0 * np.pi) + log_det)
    return out


def cumulative_loglik(model: GaussianHMM, frames: np.ndarray) -> np.ndarray:
    """log p(x_1..x_t) for t = 1..T by the forward algorithm (equals model.score(frames[:t])).

    The state distribution is kept normalised in probability space and each step's evidence
    is added in log space against its largest term, so no step underflows (about 10 us/step).
    """
    with one_thread():
        emission = _emission_loglik(model, frames)
    out = np.empty(len(frames))
    state = np.asarray(model.startprob_, dtype=np.float64)
    total = 0.0
    with np.errstate(divide="ignore"):
        for t in range(len(frames)):
            if t:
                state = state @ model.transmat_
            joint = np.log(state) + emission[t]
            peak = joint.max()
            weights = np.exp(joint - peak)
            norm = weights.sum()
            total += peak + np.log(norm)
            state = weights / norm
            out[t] = total
    return out


def curve_stats(curves: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Mean and spread (floored) of the curves at each step, over the curves that reach it.

    The table ends at the last step that two curves reach (one, if there is one curve): a
    spread needs two; the caller uses the last entry for later steps.
    """
    lengths = np.array([len(c) for c in curves])
    need = min(2, len(curves))
    horizon = int(np.sort(lengths)[-need])
    mean, std = np.empty(horizon), np.empty(horizon)
    for t in range(horizon):
        values = np.array([c[t] for c in curves if len(c) > t])
        mean[t], std[t] = values.mean(), values.std()
    std = np.maximum(std, STD_FLOOR * np.maximum(1.0, np.abs(mean)))
    return mean, std


# sklearn has no type hints, so its bases are Any: strict mypy refuses to subclass them
class HMMDetector(BaseEstimator):  # type: ignore[misc]
    """Per sub-task GaussianHMM of the successes; a step's score is how far the cumulative
    log-likelihood lies below the successes' mean at that step, in their standard deviations.

    `fit(sequences)`: sub-task name -> (T_i, d) arrays of successful trials. Each sub-task gets
    its own scaler (fitted on its successes' frames), HMM and mean/std curve. A sub-task whose
    sequences are all empty is left out (unknown: its scores are +inf).
    """

    def __init__(
        self,
        n_components: int = 5,
        covariance_type: str = "diag",
        n_iter: int = 100,
        random_state: int | None = 0,
    ) -> None:
        self.n_components = n_components
        self.covariance_type = covariance_type
        self.n_iter = n_iter
        self.random_state = random_state

    def fit(self, sequences: Mapping[str, Sequence[np.ndarray]]) -> HMMDetector:
        """Fit one scaler, HMM and mean/std log-likelihood curve per sub-task."""
        _check_params(self.n_components, self.n_iter)
        self.scalers_: dict[str, StandardScaler] = {}
        self.models_: dict[str, GaussianHMM] = {}
        self.mean_curve_: dict[str, np.ndarray] = {}
        self.std_curve_: dict[str, np.ndarray] = {}
        for phase, seqs in sequences.items():
            frames = [f for f in (as_frames(s) for s in seqs) if len(f)]
            if not frames:
                continue
            scaler = StandardScaler().fit(np.concatenate(frames))
            scaled = [scaler.transform(f) for f in frames]
            model = fit_hmm(
                scaled, self.n_components, self.covariance_type, self.n_iter, self.random_state
            )
            curves = [cumulative_loglik(model, f) for f in scaled]
            self.scalers_[phase], self.models_[phase] = scaler, model
            self.mean_curve_[phase], self.std_curve_[phase] = curve_stats(curves)
        if not self.models_:
            raise ValueError("no sub-task has a non-empty successful sequence")
        self.phases_ = tuple(sorted(self.models_))
        return self

    def loglik(self, phase: str, seq: np.ndarray) -> np.ndarray:
        """Cumulative log-likelihood (T,) of the sequence under the sub-task's HMM (KeyError for
        a sub-task not fitted)."""
        frames = as_frames(seq)
        if not len(frames):
            return np.empty(0)
        return cumulative_loglik(self.models_[phase], self.scalers_[phase].transform(frames))

    def score(self, phase: str, seq: np.ndarray) -> np.ndarray:
        """(mean_t - loglik_t) / std_t per step (T,): higher is less nominal; +inf for an
        unknown sub-task; steps past the successes' table use its last entry."""
        frames = as_frames(seq)
        if phase not in self.models_:
            return np.full(len(frames), np.inf)
        loglik = self.loglik(phase, frames)
        mean, std = self.mean_curve_[phase], self.std_curve_[phase]
        index = np.minimum(np.arange(len(loglik)), len(mean) - 1)
        scores: NDArray[np.float64] = (mean[index] - loglik) / std[index]
        return scores


# sklearn has no type hints, so its bases are Any: strict mypy refuses to subclass them
class HMMClassifier(ClassifierMixin, BaseEstimator):  # type: ignore[misc]
    """One GaussianHMM per failure class on the evidence windows; the class whose HMM gives
    the window the highest likelihood is named.

    `predict_proba`: softmax over classes of the per-frame log-likelihood log p(window) / T
    (temperature one frame; its argmax is the framework's). One scaler for all classes, so
    their likelihoods compare. A class with only empty training windows has no model and
    probability zero; an empty window gets equal probabilities for the other classes.
    """

    def __init__(
        self,
        n_components: int = 5,
        covariance_type: str = "diag",
        n_iter: int = 100,
        random_state: int | None = 0,
    ) -> None:
        self.n_components = n_components
        self.covariance_type = covariance_type
        self.n_iter = n_iter
        self.random_state = random_state

    def fit(self, windows: Sequence[np.ndarray], y: Sequence[object]) -> HMMClassifier:
        """Fit the shared scaler and one HMM per class."""
        _check_params(self.n_components, self.n_iter)
        frames = [as_frames(w) for w in windows]
        labels = np.asarray(y)
        if len(frames) != len(labels):
            raise ValueError(f"{len(frames)} windows but {len(labels)} labels")
        filled = [f for f in frames if len(f)]
        if not filled:
            raise ValueError("every training window is empty")
        self.scaler_ = StandardScaler().fit(np.concatenate(filled))
        self.classes_ = np.unique(labels)
        self.models_: list[GaussianHMM | None] = []
        for label in self.classes_:
            members = [
                self.scaler_.transform(f)
                for f, c in zip(frames, labels, strict=True)
                if c == label and len(f)
            ]
            self.models_.append(
                fit_hmm(
                    members, self.n_components, self.covariance_type, self.n_iter, self.random_state
                )
                if members
                else None
            )
        return self

    def frame_loglik(self, windows: Sequence[np.ndarray]) -> np.ndarray:
        """log p(window | class) / T per window and class (n, n_classes); -inf for a class
        without a model, 0 for the others on an empty window."""
        out = np.zeros((len(windows), len(self.classes_)))
        out[:, [m is None for m in self.models_]] = -np.inf
        for i, window in enumerate(windows):
            frames = as_frames(window)
            if not len(frames):
                continue
            scaled = self.scaler_.transform(frames)
            for j, model in enumerate(self.models_):
                if model is not None:
                    with one_thread():
                        out[i, j] = model.score(scaled) / len(frames)
        return out

    def predict_proba(self, windows: Sequence[np.ndarray]) -> np.ndarray:
        """Softmax over classes of the per-frame log-likelihood (n, n_classes)."""
        return np.asarray(softmax(self.frame_loglik(windows), axis=1))

    def predict(self, windows: Sequence[np.ndarray]) -> np.ndarray:
        """The most likely class per window."""
        return np.asarray(self.classes_[np.argmax(self.predict_proba(windows), axis=1)])

"""Failure characterisation: which failure class, and which way the part deviated (x, y, yaw).

The evidence runs from the onset on, tick by tick. Each tick gives a vector of its view (the
verifier: the mean wrench of every arm; the timing baseline: how long each sub-task has run),
summarised as its mean over each span of `evidence_s` after onset, minus a reference: for the
verifier the tick before onset, so the summary is how the contact changed the wrench (sensor
bias and gripper load cancel). An onset the detector estimated is where the change score
left the noise, and that score compares each window with the one `lag_s` before it, so the
reference is taken `lag_s` before such an onset. Beside it the verifier reads the context at
onset: the wrench at the reference against the successes' at that time into the sub-task (a
part held off centre loads the wrist differently), the time into the sub-task and which
sub-task ran; and where the task stands when the class is named: the sub-task running, the
time into it and since onset (a jam stalls a sub-task, a missed snap ends it early).
The class is named again each time a span closes and when the stream ends; between those
ticks the last naming stands, so a tick after the alarm costs only a few additions.

Heads (`Characteriser`): random forests for the class and, when the labels carry deviations, one
per axis with '-', '0', '+' (learnt from the classes whose deviations always have the same
signs), and one per axis for each class whose deviations change sign on that axis (a housing
that sits to either side), which names the directions when that class is named. Beside the
class forest votes the shape head (verify/shape.py), which reads the evidence's ticks since
onset, with the weight the training failures chose for it. Where every trial of a class deviated with the same signs and no other class shares them,
the class head's probability of "one of those deviation classes" is shared among them by the
direction heads' probabilities of their signs.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.utils import Tags
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_is_fitted, column_or_1d, validate_data

from rcbht_introspection.learn.forest import ForestHead
from rcbht_introspection.verify.labels import DIRECTION_AXES, TrialLabel
from rcbht_introspection.verify.shape import CLIP, ShapeHead, mix, vote_weight

FAILURE = "class"
"""The failure-class head's name among the heads (the others: the deviation axes)."""
VIEWS = ("wrench", "raw", "timing")
"""What a characteriser's evidence reads: the verifier's change since before onset with its
context, the raw-wrench baseline's mean wrench by time into the trial, the timing baseline's
sub-task durations."""
WINDOW_TICKS = 20_000
"""Ticks of the evidence the shape head reads (the latest; 1000 s at 20 Hz)."""


def span_index(spans: Sequence[float], since_onset: float) -> int:
    """The span of `evidence_s` a tick this long after onset falls in (len(spans): after all)."""
    return int(np.searchsorted(np.asarray(spans), since_onset - 1e-9, side="left"))


@dataclass(eq=False)
class RunningEvidence:
    """The span summaries of [onset, now], one tick at a time, in constant time per tick: the
    same numbers offline (a trial's ticks fed through it) and live (verifier_node)."""

    spans: tuple[float, ...]
    onset: float
    reference: np.ndarray
    context: np.ndarray
    sums: np.ndarray = field(init=False)
    counts: np.ndarray = field(init=False)
    high: np.ndarray = field(init=False)
    low: np.ndarray = field(init=False)
    current: int = -1
    """The span of the latest tick (-1 before the first)."""
    now: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """Where the task stands at the latest tick (`EvidenceReader.now`)."""
    ticks: deque[np.ndarray] = field(default_factory=lambda: deque(maxlen=WINDOW_TICKS))
    """The ticks' vectors since onset (the shape head's window)."""

    def __post_init__(self) -> None:
        self.sums = np.zeros((len(self.spans) + 1, len(self.reference)))
        self.counts = np.zeros(len(self.spans) + 1, dtype=int)
        self.high = np.full(len(self.reference), -np.inf)
        self.low = np.full(len(self.reference), np.inf)

    def add(self, time: float, vector: np.ndarray, now: np.ndarray | None = None) -> bool:
        """The next tick at or after onset (`now`: where the task stands at it); True when it
        opens a new span (name again)."""
        k = span_index(self.spans, time - self.onset)
        if now is not None:
            self.now = now
        v = np.clip(np.nan_to_num(vector, nan=0.0), -CLIP, CLIP)
        self.sums[k] += v
        self.counts[k] += 1
        np.maximum(self.high, v, out=self.high)
        np.minimum(self.low, v, out=self.low)
        self.ticks.append(v)
        opened = k != self.current
        self.current = k
        return opened

    def features(self) -> np.ndarray:
        """Each span's mean minus the reference (a span not reached: the last reached), the
        largest and smallest since onset minus the reference, the context, where the task
        stands now."""
        out, last = [], np.zeros(len(self.reference))
        for s, n in zip(self.sums, self.counts, strict=True):
            if n:
                last = s / n - self.reference
            out.append(last)
        if self.counts.any():
            out += [self.high - self.reference, self.low - self.reference]
        else:
            out += [last, last]
        return np.concatenate([*out, self.context, self.now])

    def window(self) -> np.ndarray:
        """(ticks, channels): the ticks' vectors since onset minus the reference (the reference
        alone before the first)."""
        seen = np.asarray(self.ticks) if self.ticks else self.reference[None, :]
        window: np.ndarray = seen - self.reference
        return window


def class_head(axis: str, failure_class: str) -> str:
    """The name of a direction head of one class: `axis@class`."""
    return f"{axis}@{failure_class}"


LABEL_COLUMNS = ("class", *DIRECTION_AXES)
"""Columns of a characteriser's two-dimensional y: the failure class, then the deviation's sign
per axis ('-', '0', '+'; '' for every axis of a trial whose label carries no deviation)."""


def label_matrix(labels: Sequence[TrialLabel]) -> np.ndarray:
    """The y of `Characteriser.fit` from trial labels: one row of LABEL_COLUMNS per label."""
    rows = []
    for lb in labels:
        d = lb.directions()
        rows.append([lb.failure_class, *(d[a] if d else "" for a in DIRECTION_AXES)])
    return np.asarray(rows, dtype=str).reshape(len(rows), len(LABEL_COLUMNS))


def _signs_by_class(y: np.ndarray) -> dict[str, set[tuple[str, ...]]]:
    """The direction signs (x, y, r) each class's labelled rows carry."""
    signs: dict[str, set[tuple[str, ...]]] = {}
    for cls, *key in y[y[:, 1] != ""]:
        signs.setdefault(str(cls), set()).add(tuple(str(k) for k in key))
    return signs


def sign_table(y: np.ndarray) -> dict[tuple[str, ...], str]:
    """Direction signs (x, y, r) -> failure class, from label rows (`label_matrix`): a class
    whose every row carries a deviation of the same signs, and whose signs no other class shares."""
    unlabelled = {str(c) for c in y[y[:, 1] == "", 0]}
    owners: dict[tuple[str, ...], list[str]] = {}
    for cls, found in _signs_by_class(y).items():
        if len(found) == 1 and cls not in unlabelled:
            owners.setdefault(next(iter(found)), []).append(cls)
    return {key: names[0] for key, names in owners.items() if len(names) == 1}


def _evidence(X: np.ndarray) -> np.ndarray:
    """Evidence rows as the heads read them: NaN as 0, clipped to +-CLIP."""
    rows: np.ndarray = np.clip(np.nan_to_num(np.asarray(X, dtype=float), nan=0.0), -CLIP, CLIP)
    return rows


class Characteriser(ClassifierMixin, BaseEstimator):  # type: ignore[misc]
    """Evidence features -> failure class, its probabilities and the deviation directions.

    `fit(X, y)` takes y as class names, or as rows of LABEL_COLUMNS (`label_matrix`) to learn
    the direction heads too; `windows` (the evidence since onset per row) add the shape head and
    `groups` (the trial of each row) hold whole trials out when its vote weight is chosen."""

    def __init__(
        self,
        n_estimators: int = 100,
        min_samples_leaf: int = 2,
        compose: bool = True,
        shape_weight: float | None = None,
        random_state: int = 0,
    ) -> None:
        self.n_estimators = n_estimators
        self.min_samples_leaf = min_samples_leaf
        self.compose = compose
        self.shape_weight = shape_weight
        """The shape head's vote weight (None: learnt from the training failures, vote_weight)."""
        self.random_state = random_state

    def __sklearn_tags__(self) -> Tags:
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = True  # NaN reads as 0, as live evidence does
        return tags

    def _head(self) -> ForestHead:
        return ForestHead(
            n_estimators=self.n_estimators,
            min_samples_leaf=self.min_samples_leaf,
            random_state=self.random_state,
        )

    def fit(
        self,
        X: np.ndarray,
        y: np.ndarray,
        windows: Sequence[np.ndarray] | None = None,
        groups: Sequence[str] | None = None,
    ) -> Characteriser:
        """The class head, the direction heads (two-dimensional y) and the shape head."""
        X, y = validate_data(self, X, y, multi_output=True, ensure_all_finite=False)
        X = _evidence(X)
        y = np.asarray(y)
        if y.ndim == 2 and y.shape[1] == len(LABEL_COLUMNS):
            y = y.astype(str)
        else:
            y = column_or_1d(y, warn=True)
        classes = y[:, 0] if y.ndim == 2 else y
        check_classification_targets(classes)
        self.heads_: dict[str, ForestHead] = {FAILURE: self._head().fit(X, classes)}
        self.classes_ = self.heads_[FAILURE].classes_
        self._fit_shape(X, classes, windows, groups)
        self.signs_: dict[tuple[str, ...], str] = {}
        if y.ndim == 2:
            self._fit_directions(X, y)
        return self

    def _fit_directions(self, X: np.ndarray, y: np.ndarray) -> None:
        """General direction heads from the classes of one set of signs (else every labelled
        row), and a class's own heads on the axes where its signs change."""
        signs = _signs_by_class(y)
        labelled = np.flatnonzero(y[:, 1] != "")
        consistent = [i for i in labelled if len(signs[y[i, 0]]) == 1]
        general = consistent or list(labelled)
        for k, axis in enumerate(DIRECTION_AXES, start=1):
            if len(labelled):
                self.heads_[axis] = self._head().fit(X[general], y[general, k])
        for cls, found in signs.items() if consistent else ():
            mine = labelled[y[labelled, 0] == cls]
            for k, axis in enumerate(DIRECTION_AXES):
                if len({key[k] for key in found}) > 1:
                    self.heads_[class_head(axis, cls)] = self._head().fit(X[mine], y[mine, k + 1])
        self.signs_ = sign_table(y) if self.compose and len(labelled) else {}

    def _fit_shape(
        self,
        X: np.ndarray,
        classes: np.ndarray,
        windows: Sequence[np.ndarray] | None,
        groups: Sequence[str] | None,
    ) -> None:
        """The shape head and its vote weight (none without windows or with one class)."""
        self.shape_: ShapeHead | None = None
        self.shape_weight_ = 0.0
        if windows is None or len(windows) != len(X) or len(set(classes)) < 2:
            return
        names = [str(c) for c in classes]
        head = ShapeHead(random_state=self.random_state)
        weight = self.shape_weight
        if weight is None:
            keys = list(groups) if groups is not None else [str(i) for i in range(len(X))]
            weight = vote_weight(self._head, head, X, windows, names, keys)
        if weight > 0:
            self.shape_, self.shape_weight_ = head.fit(windows, names), weight

    def predict_proba(
        self, X: np.ndarray, windows: Sequence[np.ndarray] | None = None
    ) -> np.ndarray:
        """(rows, classes_) probabilities: the class head, voted with the shape head where the
        rows' windows are given, the sign classes' mass shared by the direction heads."""
        check_is_fitted(self, "heads_")
        X = _evidence(validate_data(self, X, reset=False, ensure_all_finite=False))
        out = np.zeros((len(X), len(self.classes_)))
        for i, row in enumerate(X):
            window = None if windows is None else windows[i]
            probs = self._probabilities(row[None, :], window)[0]
            out[i] = [probs[str(c)] for c in self.classes_]
        return out

    def predict(self, X: np.ndarray, windows: Sequence[np.ndarray] | None = None) -> np.ndarray:
        """The likeliest class of each row."""
        proba = self.predict_proba(X, windows)
        named: np.ndarray = self.classes_[np.argmax(proba, axis=1)]
        return named

    def characterise(
        self, x: np.ndarray, window: np.ndarray | None = None
    ) -> tuple[str, dict[str, float], dict[str, str]]:
        """(class, class probabilities, direction per axis) of one evidence row (and its
        window): what the verifier names at a tick, without the array checks of predict."""
        row = _evidence(x)[None, :]
        probs, directions = self._probabilities(row, window)
        named = max(probs, key=probs.__getitem__)
        for axis in DIRECTION_AXES:  # a class with its own heads: its directions
            if (head := self.heads_.get(class_head(axis, named))) is not None:
                directions[axis] = _named(head, row)
        dirs = {a: max(p, key=p.__getitem__) for a, p in directions.items()}
        return named, probs, dirs

    def _probabilities(
        self, row: np.ndarray, window: np.ndarray | None
    ) -> tuple[dict[str, float], dict[str, dict[str, float]]]:
        """One row's class probabilities and the general direction heads' probabilities."""
        probs = _named(self.heads_[FAILURE], row)
        if self.shape_ is not None and window is not None:
            shape = self.shape_.predict_proba([window])[0]
            probs = mix(probs, shape, self.shape_.classes_, self.shape_weight_)
        directions = {a: _named(self.heads_[a], row) for a in DIRECTION_AXES if a in self.heads_}
        if self.signs_ and len(directions) == len(DIRECTION_AXES):
            probs = _shared_by_signs(probs, directions, self.signs_)
        return probs, directions


def _named(head: ForestHead, row: np.ndarray) -> dict[str, float]:
    return {str(c): float(p) for c, p in zip(head.classes_, head.shares(row)[0], strict=True)}


def _shared_by_signs(
    probs: dict[str, float],
    directions: dict[str, dict[str, float]],
    signs: dict[tuple[str, ...], str],
) -> dict[str, float]:
    """The class head's mass on the sign table's classes, shared among them in proportion to the
    direction heads' probability of each one's signs."""
    owned = {cls: key for key, cls in signs.items() if cls in probs}
    mass = sum(probs[c] for c in owned)
    belief = {
        c: float(
            np.prod([directions[a].get(s, 0.0) for a, s in zip(DIRECTION_AXES, key, strict=True)])
        )
        for c, key in owned.items()
    }
    total = sum(belief.values())
    if mass <= 0 or total <= 0:
        return probs
    return {c: (mass * belief[c] / total if c in owned else p) for c, p in probs.items()}

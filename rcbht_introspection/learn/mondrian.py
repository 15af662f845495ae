"""Mondrian forest classifier (Lakshminarayanan, Roy, Teh, NIPS 2014), batch and online.

Our own NumPy implementation of the reference algorithm: lifetime = infinity, discount
gamma = 10 * D, uniform base measure, leaves pause when pure, no bagging; the forest averages
the trees' hierarchically smoothed predictive distributions. All trees share one flat node pool
(structure-of-arrays), so prediction walks every tree of the forest at once with NumPy.
The class set grows when partial_fit meets a new label, and an optional memory budget
(max_nodes, max_points) bounds the node pool and the stored training points (docs/learning.md).
"""

from __future__ import annotations

import numbers
from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_is_fitted, check_random_state, validate_data

if TYPE_CHECKING:
    from sklearn.utils import Tags

NO_NODE = -1
POINTWISE_BATCH = 16
"""Mini-batches up to this size are added point by point across all trees (vectorised);
larger ones block by block per tree (fewer passes)."""
FEATURE_DTYPE = np.float32
"""Training data and node boxes are stored in float32 (half the memory of the wide paper
encoding); test points are cast the same way, so boxes and points compare exactly."""
COMPACT_EVERY = 1024
"""With a budget set, the stored data drops the rows no leaf keeps at least this often (in new
rows), and at once when max_points is exceeded."""


class NodePool:
    """Flat arrays of every node of every tree; grows by doubling.

    Public for the model file (learn/mondrian_state.py), which stores and rebuilds it.
    """

    def __init__(
        self, n_features: int, n_classes: int, capacity: int = 256, limit: int | None = None
    ) -> None:
        self.size = 0
        self.limit = limit
        """Capacity never grows past this (the forest's max_nodes); None: doubling only."""
        self.left = np.full(capacity, NO_NODE, dtype=np.int32)
        self.right = np.full(capacity, NO_NODE, dtype=np.int32)
        self.parent = np.full(capacity, NO_NODE, dtype=np.int32)
        self.feature = np.zeros(capacity, dtype=np.int32)
        self.threshold = np.zeros(capacity, dtype=np.float64)
        self.tau = np.full(capacity, np.inf)
        self.lower = np.zeros((capacity, n_features), dtype=FEATURE_DTYPE)
        self.upper = np.zeros((capacity, n_features), dtype=FEATURE_DTYPE)
        self.counts = np.zeros((capacity, n_classes))
        self.points: list[np.ndarray | None] = [None] * capacity

    def new(self) -> int:
        if self.size == len(self.left):
            self._grow()
        index = self.size
        self.size += 1
        self.left[index] = self.right[index] = self.parent[index] = NO_NODE
        self.tau[index] = np.inf
        self.counts[index] = 0.0
        self.points[index] = None
        return index

    def add_classes(self, position: np.ndarray, n_classes: int) -> None:
        """Widen the class counts to `n_classes` columns; old column j moves to position[j]."""
        counts = np.zeros((len(self.counts), n_classes))
        counts[:, position] = self.counts
        self.counts = counts

    def nbytes(self) -> int:
        """Bytes of the node arrays as allocated (capacity, not only the used size)."""
        names = ("left", "right", "parent", "feature", "threshold", "tau", "lower", "upper")
        total: int = sum(getattr(self, n).nbytes for n in names) + self.counts.nbytes
        return total

    def _grow(self) -> None:
        capacity = 2 * len(self.left)
        if self.limit is not None:
            capacity = max(len(self.left) + 1, min(capacity, self.limit))
        for name in ("left", "right", "parent"):
            old = getattr(self, name)
            new = np.full(capacity, NO_NODE, dtype=old.dtype)
            new[: len(old)] = old
            setattr(self, name, new)
        for name in ("feature", "threshold", "tau", "lower", "upper", "counts"):
            old = getattr(self, name)
            new = np.empty((capacity, *old.shape[1:]), dtype=old.dtype)
            new[: len(old)] = old
            setattr(self, name, new)
        self.points.extend([None] * (capacity - len(self.points)))


def _declared_classes(classes: ArrayLike, y: ArrayLike) -> np.ndarray:
    """The sorted classes partial_fit is told of; every label of the batch must be among them."""
    declared = np.unique(np.asarray(classes))
    missing = np.setdiff1d(np.unique(y), declared)
    if len(missing):
        raise ValueError(f"labels {missing.tolist()} are not in classes {declared.tolist()}")
    return declared


def _uninformed_proba(n: int, n_classes: int) -> NDArray[np.float64]:
    """The prediction of a forest that cannot tell classes apart yet (one class known, or a
    tree without a root): certainty for a single class, else uniform."""
    proba = np.zeros((n, n_classes))
    proba[:, 0] = 1.0
    if n_classes > 1:
        proba[:] = 1.0 / n_classes
    return proba


class _NewPoints(NamedTuple):
    """Points entering a block in ExtendMondrianBlock: indices, rows, box and class counts."""

    idx: NDArray[np.intp]
    data: NDArray[np.float32]
    low: NDArray[np.float32]
    high: NDArray[np.float32]
    counts: NDArray[np.float64]


@dataclass
class LearnedState:
    """What a fitted forest learned beyond its parameters: the forest's own objects, not copies.

    Handed out and taken back by the forest for its model file (learn/mondrian_state.py), so
    online training continues where it stopped.
    """

    pool: NodePool
    roots: np.ndarray
    """Root node of each tree (int32)."""
    X: np.ndarray
    """Every training point so far (FEATURE_DTYPE); paused leaves index into it."""
    y: np.ndarray
    """Class index of each training point (intp)."""
    rng: np.random.Generator
    """The random stream online updates continue with."""


# sklearn has no type hints, so its bases are Any: strict mypy refuses to subclass them
class MondrianForestClassifier(ClassifierMixin, BaseEstimator):  # type: ignore[misc]
    """Online random forest whose trees are Mondrian processes (NIPS 2014).

    Parameters: n_estimators (trees, 100 as in the seed paper), discount_factor (gamma = this
    times the number of features), random_state, and the memory budget: max_nodes (nodes of
    the whole forest, an equal share max_nodes // n_estimators per tree) and max_points
    (training points kept for regrowing leaves); None = unbounded. `partial_fit` extends every
    tree with a mini-batch so that batch and online training give the same distribution of
    forests, and adds labels it has not seen to classes_ (kept sorted).
    """

    classes_: np.ndarray
    _X: np.ndarray
    _y: np.ndarray

    def __init__(
        self,
        n_estimators: int = 100,
        discount_factor: float = 10.0,
        random_state: int | np.random.RandomState | None = None,
        max_nodes: int | None = None,
        max_points: int | None = None,
    ) -> None:
        self.n_estimators = n_estimators
        self.discount_factor = discount_factor
        self.random_state = random_state
        self.max_nodes = max_nodes
        self.max_points = max_points

    # ---------------------------------------------------------------- sklearn plumbing
    def __sklearn_tags__(self) -> Tags:
        tags = super().__sklearn_tags__()
        tags.classifier_tags.multi_class = True
        tags.non_deterministic = False
        return tags

    def _check_params(self) -> None:
        if not isinstance(self.n_estimators, numbers.Integral) or self.n_estimators < 1:
            raise ValueError(f"n_estimators must be a positive integer, got {self.n_estimators!r}")
        if not isinstance(self.discount_factor, numbers.Real) or self.discount_factor <= 0:
            raise ValueError(f"discount_factor must be > 0, got {self.discount_factor!r}")
        if self.max_nodes is not None and (
            not isinstance(self.max_nodes, numbers.Integral)
            or isinstance(self.max_nodes, bool)
            or self.max_nodes < self.n_estimators
        ):
            raise ValueError(
                f"max_nodes must be None or an integer >= n_estimators (one root per tree), "
                f"got {self.max_nodes!r}"
            )
        if self.max_points is not None and (
            not isinstance(self.max_points, numbers.Integral)
            or isinstance(self.max_points, bool)
            or self.max_points < 0
        ):
            raise ValueError(f"max_points must be None or an integer >= 0, got {self.max_points!r}")

    def fit(self, X: ArrayLike, y: ArrayLike) -> MondrianForestClassifier:
        """Grow n_estimators Mondrian trees on (X, y) from scratch."""
        self._check_params()
        checked, y = validate_data(self, X, y, dtype=np.float64)
        features = checked.astype(FEATURE_DTYPE)
        check_classification_targets(y)
        self.classes_, y_index = np.unique(y, return_inverse=True)
        self._start(features.shape[1])
        self._add_data(features, y_index)
        for tree in range(self.n_estimators):
            self._roots[tree] = self._grow(np.arange(len(y_index)), NO_NODE, 0.0, tree)
        self._forget()
        self._update_posterior()
        return self

    def partial_fit(
        self, X: ArrayLike, y: ArrayLike, classes: ArrayLike | None = None
    ) -> MondrianForestClassifier:
        """Extend every tree with a mini-batch; labels not yet known join classes_.

        `classes` may name labels before they are taught (e.g. a first mini-batch that misses
        one); it may add to the known classes but never drop one (ValueError). Without it, the
        first call starts from the labels it sees (cold start).
        """
        first = not hasattr(self, "classes_")
        if first:
            self._check_params()
        checked, y = validate_data(self, X, y, dtype=np.float64, reset=first)
        features = checked.astype(FEATURE_DTYPE)
        check_classification_targets(y)
        declared = None if classes is None else _declared_classes(classes, y)
        wanted = np.unique(y) if declared is None else declared
        if first:
            self.classes_ = wanted
            self._start(features.shape[1])
        else:
            if declared is not None and len(np.setdiff1d(self.classes_, declared)):
                raise ValueError(
                    f"classes {declared.tolist()} drop known classes "
                    f"{np.setdiff1d(self.classes_, declared).tolist()}"
                )
            self._add_classes(wanted)
        y_index = np.searchsorted(self.classes_, y).astype(np.intp)
        self._extend_forest(self._add_data(features, y_index))
        self._forget()
        self._update_posterior()
        return self

    def _extend_forest(self, new: NDArray[np.intp]) -> None:
        """Add the stored rows `new` to every tree (grow the trees if none has a root yet)."""
        if (self._roots == NO_NODE).all():
            for tree in range(self.n_estimators):
                self._roots[tree] = self._grow(new, NO_NODE, 0.0, tree)
        elif len(new) <= POINTWISE_BATCH:
            # one point at a time through all trees at once (Mondrian trees are projective:
            # extending point by point has the same distribution as extending by the batch)
            for point in new:
                self._extend_point(int(point))
        else:
            for tree in range(self.n_estimators):
                self._extend(tree, int(self._roots[tree]), new)

    def _add_classes(self, labels: np.ndarray) -> None:
        """Grow classes_ (sorted) by the new ones among `labels`: count columns and stored
        labels move to the new column order; structure and random stream are untouched."""
        if (self.classes_.dtype.kind in "biuf") != (labels.dtype.kind in "biuf"):
            raise ValueError(
                f"labels {labels} are not of the kind of the known classes {self.classes_}"
            )
        merged = np.union1d(self.classes_, labels)
        if len(merged) == len(self.classes_):
            return
        position = np.searchsorted(merged, self.classes_)
        self._pool.add_classes(position, len(merged))
        self._y = position[self._y]
        self.classes_ = merged

    # ---------------------------------------------------------------- model files
    def learned_state(self) -> LearnedState:
        """The fitted state beyond the parameters (for the model file; shared, not copied)."""
        check_is_fitted(self, "classes_")
        return LearnedState(self._pool, self._roots, self._X, self._y, self._rng)

    def restore(
        self, classes: np.ndarray, n_features: int, state: LearnedState
    ) -> MondrianForestClassifier:
        """Become the fitted forest `state` describes (a loaded model file); returns self."""
        self._check_params()
        self.classes_ = classes
        self.n_features_in_ = n_features
        self._rng = state.rng
        self._pool = state.pool
        self._pool.limit = self.max_nodes
        self._roots = state.roots
        self._X = state.X
        self._y = state.y
        self.gamma_ = self.discount_factor * n_features
        self._tree_nodes = self._count_nodes(self._roots)
        self._new_rows = 0
        self._update_posterior()
        return self

    def _count_nodes(self, roots: np.ndarray) -> np.ndarray:
        """Nodes in each tree below `roots` (roots included; NO_NODE counts 0), level by level
        for all trees at once: a restored model is swapped into a live node, so this stays cheap."""
        left, right = self._pool.left, self._pool.right
        counts = np.zeros(len(roots), dtype=np.int64)
        tree = np.flatnonzero(roots != NO_NODE)
        frontier = roots[tree].astype(np.intp)
        while len(frontier):
            counts += np.bincount(tree, minlength=len(roots))
            inner = left[frontier] != NO_NODE
            frontier, tree = (
                np.concatenate([left[frontier[inner]], right[frontier[inner]]]),
                np.concatenate([tree[inner], tree[inner]]),
            )
        return counts

    # ---------------------------------------------------------------- training
    def _start(self, n_features: int) -> None:
        """Reset the forest: empty node pool, no data, a fresh random stream."""
        self._rng = np.random.default_rng(
            check_random_state(self.random_state).randint(np.iinfo(np.int32).max)
        )
        capacity = 32 * self.n_estimators
        if self.max_nodes is not None:
            capacity = min(capacity, self.max_nodes)
        self._pool = NodePool(n_features, len(self.classes_), capacity, limit=self.max_nodes)
        self._roots = np.full(self.n_estimators, NO_NODE, dtype=np.int32)
        self._tree_nodes = np.zeros(self.n_estimators, dtype=np.int64)
        self._X = np.empty((0, n_features), dtype=FEATURE_DTYPE)
        self._y = np.empty(0, dtype=np.intp)
        self._new_rows = 0
        self.gamma_ = self.discount_factor * n_features

    def _add_data(self, X: np.ndarray, y_index: np.ndarray) -> np.ndarray:
        """Store a batch once at forest level (paused leaves index into it); return its indices."""
        start = len(self._y)
        self._X = np.concatenate([self._X, X]) if start else np.array(X, dtype=FEATURE_DTYPE)
        self._y = np.concatenate([self._y, y_index])
        self._new_rows += len(y_index)
        return np.arange(start, len(self._y))

    # ---------------------------------------------------------------- memory budget
    def _room(self, tree: int, n_nodes: int) -> bool:
        """Whether `tree` may add `n_nodes` nodes within its share of max_nodes."""
        if self.max_nodes is None:
            return True
        share = self.max_nodes // self.n_estimators
        return bool(self._tree_nodes[tree] + n_nodes <= share)

    def _new_node(self, tree: int) -> int:
        """A fresh node of `tree` in the shared pool."""
        self._tree_nodes[tree] += 1
        return self._pool.new()

    def _sealed(self, node: int) -> bool:
        """A leaf that has lost stored points (forgotten) counts more than it stores: its
        counts stay, but it never regrows from a partial set of points."""
        stored = self._pool.points[node]
        return bool(self._pool.counts[node].sum() > (0 if stored is None else len(stored)))

    def _forget(self) -> None:
        """Apply the point budget: forget the oldest stored points beyond max_points (down to
        7/8 of it, so the re-indexing runs once per max_points/8 new points) and drop the rows
        no leaf keeps any more; the forgetting leaves keep their counts (they become sealed)."""
        if self.max_nodes is None and self.max_points is None:
            return
        n = len(self._y)
        over = self.max_points is not None and n > self.max_points
        if not over and self._new_rows < COMPACT_EVERY:
            return
        cut = 0
        if over and self.max_points is not None:
            cut = n - (self.max_points - self.max_points // 8)
        points = self._pool.points
        kept: dict[int, np.ndarray] = {}
        for i in range(self._pool.size):
            stored = points[i]
            if stored is not None:  # a leaf
                kept[i] = stored[stored >= cut] if cut else stored
        keep = np.zeros(n, dtype=bool)
        if kept:
            keep[np.concatenate(list(kept.values()))] = True
        remap = np.cumsum(keep) - 1
        for i, stored in kept.items():
            points[i] = remap[stored]
        self._X = self._X[keep]
        self._y = self._y[keep]
        self._new_rows = 0

    @property
    def n_stored_points_(self) -> int:
        """Training points the forest keeps (rows of its stored data)."""
        check_is_fitted(self, "classes_")
        return len(self._y)

    def memory_bytes(self) -> dict[str, int]:
        """Bytes held by the node pool (as allocated) and by the stored points (data, labels
        and the leaves' point lists)."""
        check_is_fitted(self, "classes_")
        lists = sum(p.nbytes for p in self._pool.points[: self._pool.size] if p is not None)
        return {
            "nodes": self._pool.nbytes(),
            "points": int(self._X.nbytes + self._y.nbytes + lists),
        }

    def _paused(
        self, counts: np.ndarray, n_points: int, lower: np.ndarray, upper: np.ndarray
    ) -> bool:
        """A block pauses when its labels are all equal, it has < 2 points or zero volume."""
        return bool(np.count_nonzero(counts) <= 1 or n_points < 2 or not np.any(upper > lower))

    def _grow(
        self, points: np.ndarray, parent: int, tau_parent: float, tree: int, node: int | None = None
    ) -> int:
        """Sample a Mondrian block on `points` below `parent` (batch growth) in node `node`
        (a fresh one when None); return it. Out of node budget, a block stays a leaf that keeps
        counts only."""
        pool, X, y = self._pool, self._X, self._y
        n_classes = pool.counts.shape[1]
        root = self._new_node(tree) if node is None else node
        stack = deque([(root, points, parent, tau_parent)])
        # breadth-first when the node budget may run out inside this block (the cut-off then
        # falls level by level, not down one branch); else depth-first
        take = stack.popleft if not self._room(tree, 2 * len(points)) else stack.pop
        while stack:
            node, idx, par, tau_par = take()
            data = X[idx]
            lower, upper = data.min(axis=0), data.max(axis=0)
            counts = np.bincount(y[idx], minlength=n_classes).astype(np.float64)
            pool.parent[node] = par
            pool.lower[node], pool.upper[node] = lower, upper
            pool.counts[node] = counts
            extent = upper - lower
            if self._paused(counts, len(idx), lower, upper) or not self._room(tree, 2):
                pool.tau[node] = np.inf
                # a block that may regrow keeps its points; out of budget none can regrow
                pool.points[node] = idx if self._room(tree, 2) else idx[:0]
                continue
            rate = extent.sum()
            pool.tau[node] = tau_par + self._rng.exponential(1.0 / rate)
            dim = self._cut_dimension(extent, rate)
            cut = np.float64(self._rng.uniform(lower[dim], upper[dim]))  # float64: never rounded
            go_left = data[:, dim] <= cut
            left, right = self._new_node(tree), self._new_node(tree)
            pool.points[node] = None
            pool.feature[node], pool.threshold[node] = dim, cut
            pool.left[node], pool.right[node] = left, right
            stack.append((left, idx[go_left], node, pool.tau[node]))
            stack.append((right, idx[~go_left], node, pool.tau[node]))
        return root

    def _extend(self, tree: int, node: int, idx: NDArray[np.intp]) -> None:
        """ExtendMondrianBlock: add points `idx` to the block at `node` (may insert a parent)."""
        pool = self._pool
        stack = [(node, idx)]
        while stack:
            node, idx = stack.pop()
            if len(idx) == 0:
                continue
            new = self._new_points(idx)
            lower, upper = pool.lower[node], pool.upper[node]  # views, valid until pool.new()
            parent = int(pool.parent[node])
            tau_parent = 0.0 if parent == NO_NODE else float(pool.tau[parent])
            if pool.left[node] == NO_NODE:  # paused leaf: absorb, regrow if no longer pure
                self._absorb(tree, node, new, parent, tau_parent)
                continue
            e_lower = lower - new.low
            e_upper = new.high - upper
            np.maximum(e_lower, 0.0, out=e_lower)
            np.maximum(e_upper, 0.0, out=e_upper)
            rate = float(e_lower.sum()) + float(e_upper.sum())
            split_time = tau_parent + self._rng.exponential(1.0 / rate) if rate > 0 else np.inf
            if split_time < pool.tau[node] and self._room(tree, 2):
                near = self._cut_above(tree, node, new, e_lower, e_upper, rate, split_time)
                stack.append((node, near))
            else:
                stack.extend(self._widen_and_route(node, new))

    def _new_points(self, idx: NDArray[np.intp]) -> _NewPoints:
        """The rows, box and class counts of points `idx` entering a block (one point, the
        common case deep in a tree, needs no reductions)."""
        n_classes = self._pool.counts.shape[1]
        data = self._X[idx]
        if len(idx) == 1:
            counts = np.zeros(n_classes)
            counts[self._y[idx[0]]] = 1.0
            return _NewPoints(idx, data, data[0], data[0], counts)
        counts = np.bincount(self._y[idx], minlength=n_classes).astype(np.float64)
        return _NewPoints(idx, data, data.min(axis=0), data.max(axis=0), counts)

    def _absorb(
        self, tree: int, node: int, new: _NewPoints, parent: int, tau_parent: float
    ) -> None:
        """A paused leaf takes the new points: its box and counts widen, and it regrows as a
        fresh block once it is no longer pure (a sealed or out-of-budget leaf keeps counts only)."""
        pool = self._pool
        lower, upper = pool.lower[node], pool.upper[node]
        sealed = self._sealed(node)
        np.minimum(lower, new.low, out=lower)
        np.maximum(upper, new.high, out=upper)
        pool.counts[node] += new.counts
        if sealed or not self._room(tree, 2):
            return  # it can never regrow: counts only, the points are not kept
        points = np.concatenate([pool.points[node], new.idx])
        if self._paused(pool.counts[node], len(points), lower, upper):
            pool.points[node] = points
        else:
            self._regrow(tree, node, points, parent, tau_parent)

    def _cut_above(
        self, tree: int, node: int, new: _NewPoints, e_lower: NDArray[np.float32],
        e_upper: NDArray[np.float32], rate: float, split_time: float,
    ) -> NDArray[np.intp]:  # fmt: skip
        """Insert a parent cutting outside the box of `node` at `split_time`: the new points
        beyond the cut grow the sibling block; return those on the node's side."""
        pool = self._pool
        low, high, data = new.low, new.high, new.data
        lower, upper = pool.lower[node], pool.upper[node]
        parent = int(pool.parent[node])
        extent = e_lower.astype(np.float64) + e_upper
        dim = self._cut_dimension(extent, rate)
        # cuts stay float64 so they are never rounded onto a data value
        if self._rng.random() * extent[dim] <= e_lower[dim]:
            cut = np.float64(self._rng.uniform(low[dim], lower[dim]))
            old_is_left = False
        else:
            cut = np.float64(self._rng.uniform(upper[dim], high[dim]))
            old_is_left = True
        new_parent = self._new_node(tree)
        pool.parent[new_parent] = parent
        pool.lower[new_parent] = np.minimum(pool.lower[node], low)
        pool.upper[new_parent] = np.maximum(pool.upper[node], high)
        pool.counts[new_parent] = pool.counts[node] + new.counts
        pool.tau[new_parent] = split_time
        pool.feature[new_parent], pool.threshold[new_parent] = dim, cut
        self._replace_child(tree, parent, node, new_parent)
        pool.parent[node] = new_parent
        left_side = data[:, dim] <= cut
        idx = new.idx
        near, far = (
            (idx[left_side], idx[~left_side]) if old_is_left else (idx[~left_side], idx[left_side])
        )
        sibling = self._grow(far, new_parent, split_time, tree)
        if old_is_left:
            pool.left[new_parent], pool.right[new_parent] = node, sibling
        else:
            pool.left[new_parent], pool.right[new_parent] = sibling, node
        return near

    def _widen_and_route(self, node: int, new: _NewPoints) -> list[tuple[int, NDArray[np.intp]]]:
        """No cut above an inner node: widen its box and counts by the new points, and send
        each point on to the child its split puts it in."""
        pool = self._pool
        lower, upper = pool.lower[node], pool.upper[node]
        np.minimum(lower, new.low, out=lower)
        np.maximum(upper, new.high, out=upper)
        pool.counts[node] += new.counts
        feature, threshold = pool.feature[node], pool.threshold[node]
        idx, data = new.idx, new.data
        if len(idx) == 1:
            child = pool.left[node] if data[0, feature] <= threshold else pool.right[node]
            return [(int(child), idx)]
        go_left = data[:, feature] <= threshold
        return [(int(pool.left[node]), idx[go_left]), (int(pool.right[node]), idx[~go_left])]

    def _cut_dimension(self, extent: np.ndarray, rate: float) -> int:
        """Draw the dimension of a cut with probability proportional to `extent` (its sum is
        `rate`); the float edge of the cumulative sum never picks a dimension of zero extent."""
        dim = int(np.searchsorted(np.cumsum(extent), self._rng.random() * rate, side="right"))
        dim = min(dim, len(extent) - 1)
        while extent[dim] <= 0:
            dim -= 1
        return dim

    def _extend_point(self, point: int) -> None:
        """ExtendMondrianBlock for one point in every tree, level by level with NumPy.

        Descending through a node whose box only widens is vectorised over trees; the rare
        structural changes (a new parent cut outside a box, a leaf absorbing or regrowing) go
        through the per-tree code with the split time already drawn here.
        """
        pool = self._pool
        x, label = self._X[point], int(self._y[point])
        idx = np.array([point])
        node = self._roots.astype(np.intp)
        tau_parent = np.zeros(self.n_estimators)
        active = np.arange(self.n_estimators)
        while len(active):
            nd = node[active]
            lower, upper = pool.lower[nd], pool.upper[nd]
            e_lower = np.maximum(lower - x, 0.0)
            e_upper = np.maximum(x - upper, 0.0)
            rate = e_lower.sum(axis=1, dtype=np.float64) + e_upper.sum(axis=1, dtype=np.float64)
            leaf = pool.left[nd] == NO_NODE
            draw = self._rng.exponential(size=len(nd))
            with np.errstate(divide="ignore"):
                split_time = np.where(rate > 0, tau_parent[active] + draw / rate, np.inf)
            split = ~leaf & (split_time < pool.tau[nd])
            if self.max_nodes is not None:  # out of node budget: widen and descend instead
                share = self.max_nodes // self.n_estimators
                split &= self._tree_nodes[active] + 2 <= share
            descend = ~leaf & ~split
            dn = nd[descend]
            pool.lower[dn] = np.minimum(lower[descend], x)
            pool.upper[dn] = np.maximum(upper[descend], x)
            pool.counts[dn, label] += 1.0
            go_left = x[pool.feature[dn]] <= pool.threshold[dn]
            moving = active[descend]
            tau_parent[moving] = pool.tau[dn]
            node[moving] = np.where(go_left, pool.left[dn], pool.right[dn])
            for k in np.flatnonzero(leaf):
                self._extend(int(active[k]), int(nd[k]), idx)
            for k in np.flatnonzero(split):
                self._insert_parent(
                    int(active[k]), int(nd[k]), idx, x, e_lower[k], e_upper[k], float(rate[k]),
                    float(split_time[k]),
                )  # fmt: skip
            active = moving

    def _insert_parent(
        self, tree: int, node: int, idx: np.ndarray, x: np.ndarray, e_lower: np.ndarray,
        e_upper: np.ndarray, rate: float, split_time: float,
    ) -> None:  # fmt: skip
        """Cut outside the box of `node` for one new point: new parent, the point a new leaf."""
        pool = self._pool
        parent = int(pool.parent[node])
        extent = e_lower.astype(np.float64) + e_upper
        dim = self._cut_dimension(extent, rate)
        lower_side = self._rng.random() * extent[dim] <= e_lower[dim]
        if lower_side:
            cut = np.float64(self._rng.uniform(x[dim], pool.lower[node, dim]))
        else:
            cut = np.float64(self._rng.uniform(pool.upper[node, dim], x[dim]))
        new_parent = self._new_node(tree)
        pool.parent[new_parent] = parent
        pool.lower[new_parent] = np.minimum(pool.lower[node], x)
        pool.upper[new_parent] = np.maximum(pool.upper[node], x)
        pool.counts[new_parent] = pool.counts[node]
        pool.counts[new_parent, self._y[idx[0]]] += 1.0
        pool.tau[new_parent] = split_time
        pool.feature[new_parent], pool.threshold[new_parent] = dim, cut
        self._replace_child(tree, parent, node, new_parent)
        pool.parent[node] = new_parent
        sibling = self._grow(idx, new_parent, split_time, tree)
        if lower_side:
            pool.left[new_parent], pool.right[new_parent] = sibling, node
        else:
            pool.left[new_parent], pool.right[new_parent] = node, sibling

    def _replace_child(self, tree: int, parent: int, old: int, new: int) -> None:
        """Point `parent` (or the tree's root slot) at `new` instead of `old`."""
        pool = self._pool
        if parent == NO_NODE:
            self._roots[tree] = new
        elif pool.left[parent] == old:
            pool.left[parent] = new
        else:
            pool.right[parent] = new

    def _regrow(
        self, tree: int, node: int, points: np.ndarray, parent: int, tau_parent: float
    ) -> None:
        """Regrow the leaf `node` in place as a fresh block on `points` (an unpaused leaf)."""
        self._grow(points, parent, tau_parent, tree, node=node)

    # ---------------------------------------------------------------- posterior
    def _update_posterior(self) -> None:
        """Hierarchical (interpolated Kneser-Ney) smoothing of class counts, top-down."""
        pool = self._pool
        size = pool.size
        n_classes = pool.counts.shape[1]
        is_leaf = pool.left[:size] == NO_NODE
        cnt = pool.counts[:size].copy()
        internal = np.flatnonzero(~is_leaf)
        cnt[internal] = np.minimum(pool.counts[pool.left[internal]], 1.0) + np.minimum(
            pool.counts[pool.right[internal]], 1.0
        )
        parent = pool.parent[:size]
        tau_parent = np.where(parent == NO_NODE, 0.0, pool.tau[np.maximum(parent, 0)])
        delta = pool.tau[:size] - tau_parent
        self._cnt = cnt
        self._delta = delta
        self._posterior = np.zeros((size, n_classes))
        frontier = self._roots.copy()
        base = np.full((len(frontier), n_classes), 1.0 / n_classes)
        while len(frontier):
            c = cnt[frontier]
            tables = np.minimum(c, 1.0)
            discount = np.exp(-self.gamma_ * delta[frontier])[:, None]
            g = c - discount * tables + discount * tables.sum(axis=1, keepdims=True) * base
            g /= c.sum(axis=1, keepdims=True)
            self._posterior[frontier] = g
            inner = frontier[~is_leaf[frontier]]
            frontier = np.concatenate([pool.left[inner], pool.right[inner]])
            base = np.concatenate([self._posterior[inner], self._posterior[inner]])
        # compact views for fast prediction
        self._left = pool.left[:size].copy()
        self._right = pool.right[:size].copy()
        self._feature = pool.feature[:size].copy()
        self._threshold = pool.threshold[:size].copy()
        self._lower = pool.lower[:size]
        self._upper = pool.upper[:size]
        self._parent_posterior = np.where(
            (parent == NO_NODE)[:, None], 1.0 / n_classes, self._posterior[np.maximum(parent, 0)]
        )
        self._tables = np.minimum(cnt, 1.0)
        self._n_tables = self._tables.sum(axis=1)
        self._n_customers = cnt.sum(axis=1)

    # ---------------------------------------------------------------- prediction
    def predict_proba(self, X: ArrayLike) -> NDArray[np.float64]:
        """Mean over trees of the predictive class distribution (rows sum to 1)."""
        check_is_fitted(self, "classes_")
        features = validate_data(self, X, dtype=np.float64, reset=False).astype(FEATURE_DTYPE)
        n, n_classes, n_trees = len(features), len(self.classes_), self.n_estimators
        if n_classes == 1 or (self._roots == NO_NODE).any():
            return _uninformed_proba(n, n_classes)
        # 1. walk every (sample, tree) path down to its leaf
        paths, sample = self._leaf_paths(features)
        valid = paths != NO_NODE
        nodes = paths[valid]
        x = features[np.broadcast_to(sample, paths.shape)[valid]]
        # 2. probability that the test point separates from the tree at each node of its path
        eta, p_sep, reach = self._separation(paths, valid, nodes, x)
        # 3. posterior of a new node cut above the path node (separated) or the leaf's own
        contrib = self._path_contributions(nodes, eta, p_sep, reach)
        full = np.zeros((*paths.shape, n_classes))
        full[valid] = contrib
        per_tree = full.sum(axis=0).reshape(n, n_trees, n_classes)
        proba: NDArray[np.float64] = per_tree.mean(axis=1)
        proba /= proba.sum(axis=1, keepdims=True)
        return proba

    def _leaf_paths(self, X: NDArray[np.float32]) -> tuple[NDArray[np.int32], NDArray[np.intp]]:
        """The nodes of every (sample, tree) path from the root down to its leaf, (depth,
        n * n_trees) with NO_NODE past the leaf, and the sample of each column; all paths
        advance together one level per step."""
        sample = np.repeat(np.arange(len(X)), self.n_estimators)
        node = np.tile(self._roots, len(X))
        rows = [node]
        alive = np.flatnonzero(self._left[node] != NO_NODE)
        while len(alive):
            node = node.copy()
            nd = node[alive]
            go_left = X[sample[alive], self._feature[nd]] <= self._threshold[nd]
            node[alive] = np.where(go_left, self._left[nd], self._right[nd])
            step = np.full_like(node, NO_NODE)
            step[alive] = node[alive]
            rows.append(step)
            alive = alive[self._left[node[alive]] != NO_NODE]
        return np.stack(rows), sample

    def _separation(
        self,
        paths: NDArray[np.int32],
        valid: NDArray[np.bool_],
        nodes: NDArray[np.int32],
        x: NDArray[np.float32],
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """For each valid path node: how far the test point lies outside its box (eta), the
        probability that a cut separates the point there, and the probability that no cut
        separated it higher up the path."""
        eta = (
            np.maximum(self._lower[nodes] - x, 0.0) + np.maximum(x - self._upper[nodes], 0.0)
        ).sum(axis=1)
        delta = self._delta[nodes]
        outside = eta > 0
        p_sep = np.zeros(len(nodes))
        finite = outside & np.isfinite(delta)
        p_sep[outside] = 1.0
        p_sep[finite] = -np.expm1(-delta[finite] * eta[finite])
        sep = np.zeros(paths.shape)
        sep[valid] = p_sep
        not_before = np.ones(paths.shape)
        not_before[1:] = np.cumprod(1.0 - sep[:-1], axis=0)
        return eta, p_sep, not_before[valid]

    def _path_contributions(
        self,
        nodes: NDArray[np.int32],
        eta: NDArray[np.float64],
        p_sep: NDArray[np.float64],
        reach: NDArray[np.float64],
    ) -> NDArray[np.float64]:
        """Each path node's weighted share of the tree's prediction: the posterior of a new
        node cut above it when the point separates there, plus the leaf's own posterior."""
        contrib = np.zeros((len(nodes), len(self.classes_)))
        o = np.flatnonzero(eta > 0)
        if len(o):
            contrib[o] = (reach * p_sep)[o][:, None] * self._separated_posterior(nodes[o], eta[o])
        leaf = self._left[nodes] == NO_NODE
        contrib[leaf] += ((reach * (1.0 - p_sep))[leaf])[:, None] * self._posterior[nodes[leaf]]
        return contrib

    def _separated_posterior(
        self, nodes: NDArray[np.int32], eta: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Posterior mean of a new node cut above each of `nodes` (the test point outside its
        box by `eta`): the node's counts with the expected discount, smoothed by its parent."""
        gamma = self.gamma_
        delta = self._delta[nodes]
        d_bar = eta / (eta + gamma)
        fin = np.isfinite(delta)
        if fin.any():
            fe, fd = eta[fin], delta[fin]
            d_bar[fin] *= np.expm1(-(fe + gamma) * fd) / np.expm1(-fe * fd)
        mean: NDArray[np.float64] = (
            self._cnt[nodes]
            - d_bar[:, None] * self._tables[nodes]
            + (d_bar * self._n_tables[nodes])[:, None] * self._parent_posterior[nodes]
        ) / self._n_customers[nodes][:, None]
        return mean

    def predict(self, X: ArrayLike) -> np.ndarray:
        """The class with the largest predictive probability."""
        proba = self.predict_proba(X)
        labels: np.ndarray = self.classes_[np.argmax(proba, axis=1)]
        return labels

    # ---------------------------------------------------------------- introspection
    @property
    def n_nodes_(self) -> int:
        check_is_fitted(self, "classes_")
        return int(self._pool.size)

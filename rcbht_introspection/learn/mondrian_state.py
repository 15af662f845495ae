"""A fitted Mondrian forest as plain parameters and arrays, and back (for the safe model file).

Everything is stored, online state included (node pool, stored points, random stream, memory
budget), so a loaded forest predicts the same and continues online training where it stopped.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rcbht_introspection.learn.mondrian import (
    FEATURE_DTYPE,
    NO_NODE,
    LearnedState,
    MondrianForestClassifier,
    NodePool,
)

POOL_ARRAYS: tuple[str, ...] = (
    "left",
    "right",
    "parent",
    "feature",
    "threshold",
    "tau",
    "lower",
    "upper",
    "counts",
)
"""The NodePool arrays stored as mf_<name>, each sliced to the pool's size."""


def forest_arrays(
    forest: MondrianForestClassifier,
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Parameters and arrays that fully describe a fitted forest (including online state)."""
    state = forest.learned_state()
    pool, size = state.pool, state.pool.size
    leaves: list[int] = []
    points: list[np.ndarray] = []  # the stored points of each leaf, in node order
    for i in range(size):
        stored = pool.points[i]
        if stored is not None:
            leaves.append(i)
            points.append(stored)
    offsets = np.zeros(len(leaves) + 1, dtype=np.int64)
    offsets[1:] = np.cumsum([len(p) for p in points])
    flat = np.concatenate(points) if points else np.empty(0, np.int64)
    params = {
        "n_estimators": int(forest.n_estimators),
        "discount_factor": float(forest.discount_factor),
        "random_state": forest.random_state if isinstance(forest.random_state, int) else None,
        "max_nodes": None if forest.max_nodes is None else int(forest.max_nodes),
        "max_points": None if forest.max_points is None else int(forest.max_points),
        "n_features_in": int(forest.n_features_in_),
        "rng_state": state.rng.bit_generator.state,
    }
    arrays = {
        "mf_classes": np.asarray(forest.classes_).astype(str),
        "mf_roots": state.roots,
        **{f"mf_{name}": getattr(pool, name)[:size] for name in POOL_ARRAYS},
        "mf_X": state.X,
        "mf_y": state.y.astype(np.int64),
        "mf_leaf_nodes": np.asarray(leaves, dtype=np.int64),
        "mf_leaf_offsets": offsets,
        "mf_leaf_points": flat.astype(np.int64),
    }
    return params, arrays


def forest_from_arrays(
    params: dict[str, Any], arrays: dict[str, np.ndarray]
) -> MondrianForestClassifier:
    """Rebuild a forest from forest_arrays output; inconsistent arrays raise ValueError."""
    forest = MondrianForestClassifier(
        n_estimators=int(params["n_estimators"]),
        discount_factor=float(params["discount_factor"]),
        random_state=params["random_state"],
        max_nodes=params.get("max_nodes"),  # files written before the budget: unbounded
        max_points=params.get("max_points"),
    )
    classes = arrays["mf_classes"]
    size = len(arrays["mf_left"])
    n_features = int(params["n_features_in"])
    rng = np.random.default_rng()
    rng.bit_generator.state = params["rng_state"]
    pool = NodePool(n_features, len(classes), capacity=max(size, 1))
    pool.size = size
    for name in POOL_ARRAYS:
        value = arrays[f"mf_{name}"]
        target = getattr(pool, name)
        if value.shape != target[:size].shape:
            raise ValueError(f"array mf_{name} has shape {value.shape}")
        target[:size] = value
    links = np.concatenate(
        [pool.left[:size], pool.right[:size], pool.parent[:size], arrays["mf_roots"]]
    )
    if size == 0 or links.max() >= size or links.min() < NO_NODE:
        raise ValueError("node links point outside the node arrays")
    _check_trees(pool, arrays["mf_roots"], n_features)
    offsets, flat = arrays["mf_leaf_offsets"], arrays["mf_leaf_points"]
    n_points = len(arrays["mf_y"])
    if len(flat) and (flat.max() >= n_points or flat.min() < 0):
        raise ValueError("leaf points point outside the stored data")
    leaves = arrays["mf_leaf_nodes"]
    if len(leaves) and (leaves.min() < 0 or leaves.max() >= size):
        raise ValueError("leaf nodes point outside the node arrays")
    if (
        len(offsets) != len(leaves) + 1
        or offsets[0] != 0
        or offsets[-1] != len(flat)
        or np.any(np.diff(offsets) < 0)
    ):
        raise ValueError("leaf point offsets do not partition the stored points")
    for k, node in enumerate(leaves):
        pool.points[int(node)] = flat[offsets[k] : offsets[k + 1]].astype(np.intp)
    roots = arrays["mf_roots"].astype(np.int32)
    if len(roots) != forest.n_estimators:
        raise ValueError("number of roots differs from n_estimators")
    state = LearnedState(
        pool=pool,
        roots=roots,
        X=arrays["mf_X"].astype(FEATURE_DTYPE),
        y=arrays["mf_y"].astype(np.intp),
        rng=rng,
    )
    return forest.restore(classes, n_features, state)


def _check_trees(pool: NodePool, roots: np.ndarray, n_features: int) -> None:
    """Every split names a feature, and the links form trees: each child's parent is the node
    that names it and each root has none, so no walk from a root can loop (a crafted file with
    a valid checksum must not hang or crash prediction)."""
    size = pool.size
    inner = np.flatnonzero(pool.left[:size] != NO_NODE)
    if np.any(pool.right[inner] == NO_NODE) or np.any(
        pool.right[:size][pool.left[:size] == NO_NODE] != NO_NODE
    ):
        raise ValueError("a node has one child")
    feature = pool.feature[inner]
    if len(feature) and (feature.min() < 0 or feature.max() >= n_features):
        raise ValueError("a split names a feature the forest does not have")
    if np.any(pool.parent[pool.left[inner]] != inner) or np.any(
        pool.parent[pool.right[inner]] != inner
    ):
        raise ValueError("a child's parent is not the node that names it")
    if np.any(pool.parent[roots] != NO_NODE):
        raise ValueError("a root has a parent")

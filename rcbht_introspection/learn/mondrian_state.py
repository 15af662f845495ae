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
    offsets, flat = arrays["mf_leaf_offsets"], arrays["mf_leaf_points"]
    n_points = len(arrays["mf_y"])
    if len(flat) and (flat.max() >= n_points or flat.min() < 0):
        raise ValueError("leaf points point outside the stored data")
    for k, node in enumerate(arrays["mf_leaf_nodes"]):
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

"""Mondrian forest latency for the live classifier node: one-sample prediction, 4-sample update.

Measured on the compact encoding of the REAL golden words when the shared HIRO data is present
(else on synthetic features of the same shape), with 100 trees.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from rcbht_introspection.grammar.encoding.compact import CompactEncoding
from rcbht_introspection.learn.data import load_trials
from rcbht_introspection.learn.mondrian import MondrianForestClassifier

if TYPE_CHECKING:
    from rcbht_introspection.grammar.split import SubtaskSample

HIRO = Path(
    os.environ.get(
        "RCBHT_HIRO_DATA", Path(__file__).resolve().parents[2].parent / "shared" / "data" / "hiro"
    )
)
REAL = "REAL_HIRO_ONE_SA_SUCCESS"


def _median_ms(times: list[float]) -> float:
    return round(1000.0 * float(np.median(times)), 3)


def _real_features() -> (
    tuple[np.ndarray, list[str], np.ndarray, list[str], list[SubtaskSample], CompactEncoding] | None
):
    """(X_train, y_train, X_rest, y_rest, rest samples, fitted encoder) from REAL golden words."""
    if not (HIRO / REAL).is_dir():
        return None

    trials = [t for t in load_trials([HIRO / REAL], "golden") if t.complete]
    train = [s for t in trials[:36] for s in t.samples]
    rest = [s for t in trials[36:] for s in t.samples]
    encoder = CompactEncoding().fit(train)
    return (
        encoder.transform(train), [s.subtask for s in train],
        encoder.transform(rest), [s.subtask for s in rest], rest, encoder,
    )  # fmt: skip


def run(out_dir: Path) -> dict:
    """Median latencies (ms) of predict_proba(1 sample) and partial_fit(4 samples), 100 trees."""
    data = _real_features()
    if data is None:
        rng = np.random.default_rng(0)
        X = rng.random((184, 101))
        y = [("approach", "rotation", "insertion", "mating")[i % 4] for i in range(184)]
        X_train, y_train, X_rest, y_rest = X[:144], y[:144], X[144:], y[144:]
        real: tuple[list[SubtaskSample], CompactEncoding] | None = None  # no samples to encode
        source = "synthetic 184 x 101"
    else:
        X_train, y_train, X_rest, y_rest, rest, encoder = data
        real = (rest, encoder)
        source = f"{REAL} golden words, compact encoding"
    forest = MondrianForestClassifier(n_estimators=100, random_state=0)
    began = time.perf_counter()
    forest.fit(X_train, y_train)
    fit_s = time.perf_counter() - began
    forest.predict_proba(X_rest[:1])  # warm-up
    predict = []
    for _ in range(3):
        for row in X_rest:
            t0 = time.perf_counter()
            forest.predict_proba(row[None, :])
            predict.append(time.perf_counter() - t0)
    with_encoding = []
    if real is not None:
        rest, encoder = real
        for sample in rest:
            t0 = time.perf_counter()
            forest.predict_proba(encoder.transform([sample]))
            with_encoding.append(time.perf_counter() - t0)
    updates = []
    for start in range(0, len(X_rest) - 3, 4):
        t0 = time.perf_counter()
        forest.partial_fit(X_rest[start : start + 4], y_rest[start : start + 4])
        updates.append(time.perf_counter() - t0)
    return {
        "data": source,
        "n_features": int(X_train.shape[1]),
        "n_estimators": 100,
        "fit_seconds": round(fit_s, 3),
        "predict_proba_1_sample_ms": _median_ms(predict),
        "predict_proba_1_sample_with_encoding_ms": _median_ms(with_encoding)
        if with_encoding
        else None,
        "partial_fit_4_samples_ms": _median_ms(updates),
        "n_nodes": forest.n_nodes_,
        "targets": {"predict_proba_1_sample_ms": 2.0, "partial_fit_4_samples_ms": 50.0},
    }

"""Mondrian forest latency for the live classifier node: one-sample prediction, 4-sample update,
and the forest's memory after 10,000 taught samples with and without a memory budget.

Latency is measured on the compact encoding of the REAL golden words when the shared HIRO data
is present (else on synthetic features of the same shape), with 100 trees; memory on synthetic
features shaped like the compact encoding (10,000 samples are more than the data holds).
"""

from __future__ import annotations

import io
import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from rcbht_introspection.grammar.encoding.compact import CompactEncoding
from rcbht_introspection.learn.data import load_trials
from rcbht_introspection.learn.mondrian import MondrianForestClassifier
from rcbht_introspection.learn.mondrian_state import forest_arrays
from rcbht_introspection.learn.online import load_teach_config

if TYPE_CHECKING:
    from rcbht_introspection.grammar.split import SubtaskSample

HIRO = Path(
    os.environ.get(
        "RCBHT_HIRO_DATA", Path(__file__).resolve().parents[2].parent / "shared" / "data" / "hiro"
    )
)
REAL = "REAL_HIRO_ONE_SA_SUCCESS"
TAUGHT = 10_000
"""Samples taught one window at a time for the memory figure."""
WINDOW = 16
"""Samples per partial_fit call: a taught window with its prefixes, the largest batch that still
goes point by point (mondrian.POINTWISE_BATCH); 625 updates keep the unbounded run to minutes."""


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


def run(out_dir: Path) -> dict[str, Any]:
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
        "memory_after_10000_taught": run_memory(),
    }


def compact_like(n: int, n_classes: int = 6, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Synthetic samples shaped like the compact encoding: 90 sparse word counts drawn from
    overlapping per-class Poisson rates and 11 log-normal durations/levels (101 features)."""
    rng = np.random.default_rng(seed)
    rates = rng.gamma(0.5, 2.0, size=(n_classes, 90))
    scales = rng.normal(0.0, 0.5, size=(n_classes, 11))
    y = rng.integers(0, n_classes, size=n)
    counts = rng.poisson(rates[y])
    levels = np.exp(scales[y] + rng.normal(0.0, 0.6, size=(n, 11)))
    return np.hstack([counts, levels]), y


def _rss_mb() -> tuple[float, float]:
    """(resident, peak resident) MB of this process, from /proc/self/status."""
    fields = dict(line.split(":", 1) for line in Path("/proc/self/status").read_text().splitlines())
    return (int(fields["VmRSS"].split()[0]) / 1024, int(fields["VmHWM"].split()[0]) / 1024)


def forest_memory(budget: dict[str, int | None]) -> dict[str, object]:
    """Teach TAUGHT compact-like samples WINDOW at a time (100 trees) under `budget`; the
    forest's own byte count, the process's resident memory, model-file size and held-out
    accuracy. Run in a fresh process so the resident figures are this forest's alone."""
    X, y = compact_like(TAUGHT + 2_000)
    forest = MondrianForestClassifier(
        n_estimators=100,
        random_state=0,
        max_nodes=budget["max_nodes"],
        max_points=budget["max_points"],
    )
    rss_before, _ = _rss_mb()
    began = time.perf_counter()
    forest.partial_fit(X[:WINDOW], y[:WINDOW], classes=np.unique(y))
    for start in range(WINDOW, TAUGHT, WINDOW):
        forest.partial_fit(X[start : start + WINDOW], y[start : start + WINDOW])
    seconds = time.perf_counter() - began
    rss_after, rss_peak = _rss_mb()
    _, arrays = forest_arrays(forest)
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)  # type: ignore[arg-type]
    own = forest.memory_bytes()
    return {
        **budget,
        "n_nodes": forest.n_nodes_,
        "n_stored_points": forest.n_stored_points_,
        "node_pool_mb": round(own["nodes"] / 2**20, 1),
        "stored_points_mb": round(own["points"] / 2**20, 1),
        "rss_growth_mb": round(rss_after - rss_before, 1),
        "rss_peak_mb": round(rss_peak, 1),
        "model_arrays_compressed_mb": round(buffer.tell() / 2**20, 1),
        "held_out_accuracy": round(float(forest.score(X[TAUGHT:], y[TAUGHT:])), 4),
        "teach_seconds": round(seconds, 1),
    }


def run_memory() -> dict[str, object]:
    """Forest memory after TAUGHT taught samples, unbounded and with config/teach.yaml's
    budget (each in its own process)."""
    spawn = multiprocessing.get_context("spawn")
    figures: dict[str, object] = {
        "data": f"synthetic compact-like, 101 features, 6 classes, {TAUGHT} samples taught "
        f"{WINDOW} per partial_fit, 100 trees; accuracy on 2000 more",
    }
    teach = load_teach_config()  # the budget a taught node's forest has
    budget_of_teaching = {"max_nodes": teach.max_nodes, "max_points": teach.max_points}
    unbounded: dict[str, int | None] = {"max_nodes": None, "max_points": None}
    for name, budget in (("unbounded", unbounded), ("budget", budget_of_teaching)):
        with ProcessPoolExecutor(max_workers=1, mp_context=spawn) as pool:
            figures[name] = pool.submit(forest_memory, budget).result()
    return figures

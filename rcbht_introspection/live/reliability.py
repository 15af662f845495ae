"""Reliability of a classifier's probabilities: the expected calibration error of its top label.

A planner reads a belief's probability as "how often is this right"; the expected calibration
error (ECE) says how far that is off on held-out data: the confidences (the leading class's
probability) are put into `n_bins` equal-width bins over [0, 1], and the ECE is the mean over bins,
weighted by their share of the samples, of |fraction correct - mean confidence| (the per-bin
figures sklearn.calibration.calibration_curve gives with strategy="uniform").
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def top_label(
    probabilities: Sequence[Sequence[float]], classes: Sequence[str], truth: Sequence[str]
) -> tuple[np.ndarray, np.ndarray]:
    """(confidence, correct) per sample: the leading class's probability and whether it is `truth`."""
    p = np.asarray(probabilities, dtype=float).reshape(len(truth), len(classes))
    lead = np.argmax(p, axis=1)
    names = np.asarray(classes, dtype=object)
    return p[np.arange(len(p)), lead], names[lead] == np.asarray(truth, dtype=object)


def expected_calibration_error(
    confidences: Sequence[float] | np.ndarray,
    correct: Sequence[bool] | np.ndarray,
    n_bins: int = 10,
) -> float | None:
    """ECE of top-label confidences against correctness (None without samples)."""
    conf = np.asarray(confidences, dtype=float)
    hit = np.asarray(correct, dtype=float)
    if conf.size == 0:
        return None
    if conf.shape != hit.shape or n_bins < 1:
        raise ValueError("confidences and correct must have one shape, n_bins >= 1")
    edges = np.linspace(0.0, 1.0, n_bins + 1)
    # calibration_curve's binning (searchsorted on the inner edges, side "left": a confidence
    # on an edge belongs to the bin below it)
    idx = np.searchsorted(edges[1:-1], conf, side="left")
    counts = np.bincount(idx, minlength=n_bins)
    gap = np.abs(
        np.bincount(idx, weights=hit, minlength=n_bins)
        - np.bincount(idx, weights=conf, minlength=n_bins)
    )
    return float(gap.sum() / counts.sum())

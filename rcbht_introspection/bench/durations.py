"""Summary figures of measured durations, as every latency benchmark reports them."""

from __future__ import annotations

import numpy as np


def ms_summary(seconds: list[float], count: str) -> dict[str, float]:
    """Count (under the key `count`), median, p99 and max of `seconds`, in ms to 3 decimals."""
    ms = 1000.0 * np.asarray(seconds)
    return {
        count: len(ms),
        "median_ms": round(float(np.median(ms)), 3),
        "p99_ms": round(float(np.percentile(ms, 99)), 3),
        "max_ms": round(float(ms.max()), 3),
    }

"""Wrench windows of any length as a panel of equal length: what MiniRocket reads (the verifier's
shape head, the peers' MiniRocket)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def resample(window: np.ndarray, n_points: int) -> np.ndarray:
    """(T, d) -> (d, n_points) by linear interpolation along time; T = 1 repeats the frame."""
    frames = np.asarray(window, dtype=np.float64)
    if frames.ndim == 1:
        frames = frames[:, None]
    if frames.ndim != 2 or len(frames) == 0:
        raise ValueError(f"a window must be (T >= 1, d), got shape {frames.shape}")
    old = np.linspace(0.0, 1.0, len(frames))
    new = np.linspace(0.0, 1.0, n_points)
    return np.stack([np.interp(new, old, channel) for channel in frames.T])


def to_panel(windows: Sequence[np.ndarray], n_points: int) -> np.ndarray:
    """(n_cases, n_channels, n_points) for aeon."""
    return np.stack([resample(w, n_points) for w in windows])

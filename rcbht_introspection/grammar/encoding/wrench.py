"""The words + wrench encoding: the compact word features without absolute wrench values, plus
the wrench since the window began relative to its level at that start and to the stream's first
block.

Both references cancel a constant sensor bias; relative to the window's start a load held
through the window cancels too, relative to the stream's start it stays (what the task has
changed since free motion). The absolute mean values of the words (compact's `mean_value`) are
left out. Per arm and axis: statistics of the block means (summaries/blocks.py) ending in the
window (STATS).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar.encoding.axes import AxisMemo
from rcbht_introspection.grammar.encoding.cache import SampleCache
from rcbht_introspection.grammar.encoding.compact import CompactEncoding
from rcbht_introspection.grammar.split import SubtaskSample
from rcbht_introspection.taxonomy.words import AXES

STATS = ("last", "mean", "min", "max", "std", "q1", "q2", "q3", "q4", "level_last", "level_mean")
"""Statistics of each axis's block means over the window. Relative to the block before the
window: last, mean, min, max, spread, and the means of its four quarters (in blocks), the shape
of the departure. Relative to the stream's first block (WrenchTrack.origin): last and mean, where
the task has taken the wrench since free motion."""


def wrench_feature_names(arms: Sequence[str]) -> list[str]:
    """Names of the wrench features, 'arm/wrench/axis/stat', in column order."""
    return [f"{arm}/wrench/{axis}/{stat}" for arm in arms for axis in AXES for stat in STATS]


def wrench_features(sample: SubtaskSample, arms: Sequence[str]) -> NDArray[np.float64]:
    """The wrench features of one window (zeros for an arm without blocks in it)."""
    out = np.zeros((len(arms), len(AXES), len(STATS)))
    for row, arm in enumerate(arms):
        track = sample.wrench.get(arm)
        if track is None:
            continue
        base, means = track.window(sample.start, sample.end)
        if not len(means):
            continue
        rel = means - base
        out[row, :, 0] = rel[-1]
        out[row, :, 1] = rel.mean(axis=0)
        out[row, :, 2] = rel.min(axis=0)
        out[row, :, 3] = rel.max(axis=0)
        out[row, :, 4] = rel.std(axis=0)
        quarter = (np.arange(len(rel)) * 4) // len(rel)
        for q in range(4):
            part = rel[quarter == q]
            out[row, :, 5 + q] = part.mean(axis=0) if len(part) else rel[-1]
        origin = base if track.origin is None else track.origin
        out[row, :, 9] = means[-1] - origin
        out[row, :, 10] = means.mean(axis=0) - origin
    flat: NDArray[np.float64] = out.reshape(-1)
    return flat


@dataclass
class WordsWrenchEncoding:
    """Compact word features (no absolute values) beside the relative wrench of the window."""

    name: str = "words-wrench"
    words: CompactEncoding = field(default_factory=lambda: CompactEncoding(values=False))
    arms: tuple[str, ...] = ()
    lower: list[float] = field(default_factory=list)
    scale: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.words.values:
            raise InputError("the words-wrench encoding reads no absolute word values")

    @property
    def cache(self) -> SampleCache:
        return self.words.cache

    @property
    def feature_names(self) -> list[str]:
        return [*self.words.feature_names, *wrench_feature_names(self.arms)]

    @property
    def n_features(self) -> int:
        return self.words.n_features + len(self.arms) * len(AXES) * len(STATS)

    def _wrench(self, samples: Sequence[SubtaskSample]) -> NDArray[np.float64]:
        width = len(self.arms) * len(AXES) * len(STATS)
        matrix = np.empty((len(samples), width))
        for row, sample in enumerate(samples):
            matrix[row] = wrench_features(sample, self.arms)
        return matrix

    def fit(self, samples: Sequence[SubtaskSample]) -> WordsWrenchEncoding:
        """Fit the word features; fix the wrench features' min-max bounds on `samples`."""
        self.words.fit(samples)
        self.arms = self.words.arms
        matrix = self._wrench(samples)
        low, high = matrix.min(axis=0), matrix.max(axis=0)
        self.lower = low.tolist()
        self.scale = np.where(high > low, high - low, 1.0).tolist()
        return self

    def transform(
        self, samples: Sequence[SubtaskSample], memo: AxisMemo | None = None
    ) -> NDArray[np.float64]:
        """(len(samples), n_features): the scaled word features, then the scaled wrench ones."""
        wrench = (self._wrench(samples) - np.asarray(self.lower)) / np.asarray(self.scale)
        out: NDArray[np.float64] = np.hstack([self.words.transform(samples, memo), wrench])
        return out

    def to_state(self) -> dict[str, Any]:
        """The fitted parameters, as stored in a model file."""
        return {
            "name": self.name,
            "words": self.words.to_state(),
            "arms": list(self.arms),
            "lower": list(self.lower),
            "scale": list(self.scale),
        }

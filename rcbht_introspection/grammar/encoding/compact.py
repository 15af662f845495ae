"""The compact encoding: per arm, level and axis the label counts, duration fractions, label
bigrams and the duration-weighted mean value of the words, plus the log sub-task duration.

Features constant on the training data are dropped, at most k are kept by pairwise ANOVA F
ranking (selection.py), the rest are min-max scaled with bounds fixed at fit time.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar.encoding.axes import AxisMemo, add_axis_features
from rcbht_introspection.grammar.encoding.cache import SampleCache
from rcbht_introspection.grammar.encoding.labels import sample_arms
from rcbht_introspection.grammar.encoding.selection import pairwise_selection
from rcbht_introspection.grammar.split import SubtaskSample
from rcbht_introspection.taxonomy.words import AXES, LEVELS, Level

VALUE_KEYS: dict[Level, str] = {
    Level.PRIMITIVE: "Average",
    Level.COMPOSITION: "Average Val",
    Level.BEHAVIOR: "AVG_MAG_VAL",
}
"""The record field holding a word's mean wrench value, per level."""
MIN_DURATION = 1e-3
"""Floor (s) for the log sub-task duration, so a zero-length window stays finite."""


def compact_raw_features(
    sample: SubtaskSample, arms: Sequence[str], memo: AxisMemo | None = None
) -> dict[str, float]:
    """Unscaled compact features of one sample (names are 'arm/level/axis/kind:label').

    Bit-identical to the plain definition (`compact_raw_features_reference`, see axes.py).
    With `memo` (the caller's, one per stream of running windows), unchanged axes are taken
    from it and it is updated with the others.
    """
    features: dict[str, float] = {}
    duration = max(sample.duration, 0.0)
    features["log_duration"] = math.log(max(duration, MIN_DURATION))
    for arm in arms:
        for level in LEVELS:
            value_key = VALUE_KEYS[level]
            for axis in AXES:
                words = sample.words.axis_words(arm, level, axis)
                if not words:
                    continue
                prefix = f"{arm}/{level.value}/{axis}/"
                if memo is not None:
                    features.update(memo.features(prefix, words, value_key))
                else:
                    add_axis_features(features, prefix, words, value_key)
    return features


@dataclass
class CompactEncoding:
    """Label counts, duration fractions, bigrams and mean values per arm/level/axis + log duration."""

    name: str = "compact"
    values: bool = True
    """Include the duration-weighted mean wrench value of each level/axis."""
    bigrams: bool = True
    """Include label bigram counts."""
    k: int | None = 100
    """Keep the k features with the largest ANOVA F score on the training labels (None: all)."""
    arms: tuple[str, ...] = ()
    feature_names: list[str] = field(default_factory=list)
    lower: list[float] = field(default_factory=list)
    scale: list[float] = field(default_factory=list)
    cache: SampleCache = field(default_factory=SampleCache, repr=False, compare=False)
    """Each sample's raw features (not stored in the model; may be shared between encodings)."""

    def _raw(self, sample: SubtaskSample) -> dict[str, float]:
        return self.cache.get(
            sample, ("compact", self.arms), lambda: compact_raw_features(sample, self.arms)
        )

    def _keep(self, name: str) -> bool:
        if not self.values and name.endswith("/mean_value"):
            return False
        return self.bigrams or "/bigram:" not in name

    def fit(self, samples: Sequence[SubtaskSample]) -> CompactEncoding:
        """Keep features that vary over the training samples; fix their min-max bounds."""
        if not samples:
            raise InputError("cannot fit the compact encoding on zero samples")
        self.arms = sample_arms(samples)
        raws = [self._raw(s) for s in samples]
        names = sorted({k for raw in raws for k in raw if self._keep(k)})
        matrix = np.array([[raw.get(k, 0.0) for k in names] for raw in raws])
        low, high = matrix.min(axis=0), matrix.max(axis=0)
        keep = high > low
        labels = [s.subtask for s in samples]
        if self.k is not None and keep.sum() > self.k and len(set(labels)) > 1:
            columns = np.flatnonzero(keep)
            chosen = pairwise_selection(matrix[:, keep], labels, self.k)
            keep = np.zeros_like(keep)
            keep[columns[chosen]] = True
        if "log_duration" in names:
            keep[names.index("log_duration")] = True
        self.feature_names = [k for k, kept in zip(names, keep, strict=True) if kept]
        self.lower = low[keep].tolist()
        self.scale = np.where(high > low, high - low, 1.0)[keep].tolist()
        return self

    @property
    def n_features(self) -> int:
        """Number of kept features."""
        return len(self.feature_names)

    def transform(
        self, samples: Sequence[SubtaskSample], memo: AxisMemo | None = None
    ) -> np.ndarray:
        """(len(samples), n_features) scaled features.

        With `memo` the samples are running windows of the memo owner's stream: their raw
        features come through the memo and bypass the sample cache (they are not asked again).
        """
        lower, scale = np.asarray(self.lower), np.asarray(self.scale)
        out = np.empty((len(samples), self.n_features))
        for row, sample in enumerate(samples):
            raw = (
                self._raw(sample) if memo is None else compact_raw_features(sample, self.arms, memo)
            )
            out[row] = [raw.get(k, 0.0) for k in self.feature_names]
        scaled: NDArray[np.float64] = (out - lower) / scale
        return scaled

    def to_state(self) -> dict[str, Any]:
        """The fitted parameters, as stored in a model file."""
        return {
            "name": self.name,
            "values": self.values,
            "bigrams": self.bigrams,
            "k": self.k,
            "arms": list(self.arms),
            "feature_names": list(self.feature_names),
            "lower": list(self.lower),
            "scale": list(self.scale),
        }

"""The plain definitions the package's fast paths are tested against (test oracles): the
compact encoding's per-word features, the paper encoding's label resampling, and the taxonomy's
whole-trial context and behaviour scan."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np

from rcbht_introspection.grammar.encoding.compact import MIN_DURATION, VALUE_KEYS
from rcbht_introspection.grammar.encoding.labels import LABEL_ALIASES
from rcbht_introspection.grammar.encoding.paper import label_arrays, resample_arrays
from rcbht_introspection.grammar.split import SubtaskSample
from rcbht_introspection.taxonomy.behavior_ops import ComposeBehaviors
from rcbht_introspection.taxonomy.config import TaxonomyConfig
from rcbht_introspection.taxonomy.ops import Row, StreamContext, run_ops
from rcbht_introspection.taxonomy.words import AXES, LEVELS, Level, Word


def compact_raw_features_reference(sample: SubtaskSample, arms: Sequence[str]) -> dict[str, float]:
    """The plain per-word definition of `compact_raw_features` (its test oracle)."""
    features: dict[str, float] = {}
    duration = max(sample.duration, 0.0)
    features["log_duration"] = math.log(max(duration, MIN_DURATION))
    for arm in arms:
        for level in LEVELS:
            value_key = VALUE_KEYS[level]
            for axis in AXES:
                words = sorted(sample.words.axis_words(arm, level, axis), key=lambda w: w.start)
                prefix = f"{arm}/{level.value}/{axis}/"
                if not words:
                    continue
                labels = [LABEL_ALIASES.get(w.label.strip(), w.label.strip()) for w in words]
                spans = [max(w.end - w.start, 0.0) for w in words]
                total = sum(spans)
                weights = spans if total > 0 else [1.0] * len(words)
                wsum = sum(weights)
                features[prefix + "n_words"] = math.log1p(len(words))
                for label, weight in zip(labels, weights, strict=True):
                    key = prefix + "count:" + label
                    features[key] = features.get(key, 0.0) + 1.0
                    key = prefix + "frac:" + label
                    features[key] = features.get(key, 0.0) + weight / wsum
                for a, b in itertools.pairwise(labels):
                    key = prefix + f"bigram:{a}>{b}"
                    features[key] = features.get(key, 0.0) + 1.0
                mean = sum(
                    w.features.get(value_key, 0.0) * wt
                    for w, wt in zip(words, weights, strict=True)
                )
                features[prefix + "mean_value"] = mean / wsum
    for key in list(features):
        if "/count:" in key or "/bigram:" in key:
            features[key] = math.log1p(features[key])
    return features


def resample_labels(words: Sequence[Word], level: Level, n: int) -> np.ndarray:
    """Spec 3 'slice_and_find_mode': n equal-duration bins, each the label covering it longest.

    Times run from the first word's start to the last word's end (words sorted by start);
    ties go to the label that appears first. An empty sequence gives -1 everywhere.
    """
    return resample_arrays(*label_arrays(words, level), n)


def whole_context(
    config: TaxonomyConfig, state_times: Sequence[float], end_time: float
) -> StreamContext:
    """The context of a complete trial (every boundary and the end known)."""
    return StreamContext(
        config, boundaries=list(state_times), now=math.inf, ended=True, end_time=end_time
    )


def compose_behaviors(mcs: list[Row], config: TaxonomyConfig) -> list[Row]:
    """llbehComposition's scan on a whole axis (before refinement)."""
    return run_ops([ComposeBehaviors(config)], mcs)

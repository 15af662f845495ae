"""The paper's encoding (spec 3): resampled label-index vectors.

One n per level = the longest label sequence in the training data (REAL golden labels give 6204
features, SIM 1428); each arm/level/axis sequence is cut into n equal-duration bins, each bin
holding the index of the label covering it longest.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar.encoding.cache import SampleCache
from rcbht_introspection.grammar.encoding.labels import label_index, sample_arms
from rcbht_introspection.grammar.split import SubtaskSample
from rcbht_introspection.taxonomy.words import AXES, LEVELS, Level, Word

if TYPE_CHECKING:
    from rcbht_introspection.grammar.encoding.axes import AxisMemo


def label_arrays(words: Sequence[Word], level: Level) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(starts, ends, label indices) of a word sequence sorted by start time."""
    ordered = sorted(words, key=lambda w: w.start)
    starts = np.array([w.start for w in ordered], dtype=float)
    ends = np.maximum(np.array([w.end for w in ordered], dtype=float), starts)
    codes = np.array([label_index(level, w.label) for w in ordered], dtype=int)
    return starts, ends, codes


def _axis_label_arrays(
    sample: SubtaskSample, arm: str, level: Level, axis: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """label_arrays of one arm/level/axis word sequence of `sample`."""
    return label_arrays(sample.words.axis_words(arm, level, axis), level)


def resample_arrays(starts: np.ndarray, ends: np.ndarray, codes: np.ndarray, n: int) -> np.ndarray:
    """resample_labels on the output of label_arrays (lets callers cache the label arrays)."""
    out = np.full(n, -1.0)
    if not len(starts) or n <= 0:
        return out
    t0, t1 = starts[0], max(ends[-1], starts[0])
    edges = t0 + (t1 - t0) * np.arange(n + 1) / n
    kinds = list(dict.fromkeys(codes.tolist()))  # first-appearance order breaks ties
    mass = np.empty((len(kinds), n))
    for row, kind in enumerate(kinds):
        mask = codes == kind
        mass[row] = np.diff(_coverage(edges, starts[mask], ends[mask]))
    out[:] = np.asarray(kinds, dtype=float)[np.argmax(mass, axis=0)]
    return out


def _coverage(edges: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Total length of the intervals [starts, ends] lying left of each edge (piecewise linear)."""
    times = np.concatenate([starts, ends])
    slopes = np.concatenate([np.ones(len(starts)), -np.ones(len(ends))])
    order = np.argsort(times, kind="stable")
    times, slopes = times[order], np.cumsum(slopes[order])
    values = np.concatenate([[0.0], np.cumsum(slopes[:-1] * np.diff(times))])
    covered: NDArray[np.float64] = np.interp(edges, times, values)
    return covered


def _uncached(sample: SubtaskSample, key: Any, compute: Callable[[], Any]) -> Any:
    """SampleCache.get without the cache: for transient samples (running windows)."""
    return compute()


@dataclass
class PaperEncoding:
    """Spec 3 vectors: per arm, level (primitive, composition, behavior) and axis, n_level bins."""

    name: str = "paper"
    arms: tuple[str, ...] = ()
    n: dict[str, int] = field(default_factory=dict)
    cache: SampleCache = field(default_factory=SampleCache, repr=False, compare=False)
    """Each sample's label arrays and bins (not stored in the model; may be shared)."""

    def fit(self, samples: Sequence[SubtaskSample]) -> PaperEncoding:
        """n per level = the longest label sequence over the training samples, arms and axes."""
        if not samples:
            raise InputError("cannot fit the paper encoding on zero samples")
        self.arms = sample_arms(samples)
        self.n = {
            level.value: max(
                1,
                max(
                    len(s.words.axis_words(arm, level, axis))
                    for s in samples
                    for arm in self.arms
                    for axis in AXES
                ),
            )
            for level in LEVELS
        }
        return self

    @property
    def n_features(self) -> int:
        """Length of a feature vector: arms x axes x the sum of the levels' n."""
        return len(self.arms) * len(AXES) * sum(self.n.values())

    def transform(
        self, samples: Sequence[SubtaskSample], memo: AxisMemo | None = None
    ) -> np.ndarray:
        """(len(samples), n_features) label indices.

        `memo` marks the samples as running windows: there is no incremental form of this
        encoding, but such samples are transient, so they bypass the sample cache.
        """
        get = self.cache.get if memo is None else _uncached
        out = np.empty((len(samples), self.n_features))
        for row, sample in enumerate(samples):
            parts = []
            for arm in self.arms:
                for level in LEVELS:
                    n = self.n[level.value]
                    for axis in AXES:
                        arrays: tuple[np.ndarray, np.ndarray, np.ndarray] = get(
                            sample,
                            ("labels", arm, level, axis),
                            partial(_axis_label_arrays, sample, arm, level, axis),
                        )
                        parts.append(
                            get(
                                sample,
                                ("paper", arm, level, axis, n),
                                partial(resample_arrays, *arrays, n),
                            )
                        )
            out[row] = np.concatenate(parts)
        return out

    def to_state(self) -> dict[str, Any]:
        """The fitted parameters, as stored in a model file."""
        return {"name": self.name, "arms": list(self.arms), "n": dict(self.n)}

"""The compact features of one arm/level/axis word sequence, and AxisMemo: their incremental reuse.

Two paths give bit-identical floats: NumPy over long sequences, plain Python with per-label keys
over short ones (NumPy's fixed cost dominates there); every sum is taken in the word order of
the plain definition (compact_raw_features_reference in test/references.py). A running window
owns an AxisMemo (the belief tracker keeps one per stream) and hands it to the encoding explicitly.
"""

from __future__ import annotations

import itertools
import math
import operator
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from rcbht_introspection.grammar.encoding.labels import LABEL_ALIASES
from rcbht_introspection.taxonomy.words import Word

NUMPY_MIN_WORDS = 128
"""Sequences at least this long get NumPy compact features (measured break-even ~120 words)."""


def add_axis_features(
    features: dict[str, float], prefix: str, words: Sequence[Word], value_key: str
) -> None:
    """Add the compact features of one arm/level/axis word sequence to `features` (either path)."""
    if len(words) < NUMPY_MIN_WORDS:
        _axis_features_small(features, prefix, words, value_key)
    else:
        _axis_features(features, prefix, words, value_key)


@dataclass
class _AxisEntry:
    words: list[Word]
    features: dict[str, float]
    arrays: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
    """(starts, ends, values, label codes) of a long, start-ordered sequence."""
    names: dict[str, int] = field(default_factory=dict)
    """Label -> code, in order of first appearance."""


class AxisMemo:
    """The compact features of each axis' last word sequence, reused while it is unchanged.

    A running window grows by a few words per update on one or two of its axes; the others'
    features come from here, and a grown long sequence only converts its new words to arrays.
    Results are bit-identical: same words, same arrays, same computation. Same words means the
    same objects, except the edge words, which a window clips into new ones: compared by value.
    One memo serves one stream of windows; its owner passes it to the encoding explicitly.
    """

    def __init__(self) -> None:
        self.entries: dict[str, _AxisEntry] = {}

    def features(self, prefix: str, words: Sequence[Word], value_key: str) -> dict[str, float]:
        """The features of `words` under `prefix` (computed unless the last sequence was the same)."""
        old = self.entries.get(prefix)
        if old is not None and _same_words(old.words, words):
            return old.features
        entry = _AxisEntry(list(words), {})
        if len(words) < NUMPY_MIN_WORDS:
            _axis_features_small(entry.features, prefix, words, value_key)
        else:
            if old is not None and old.arrays is not None and _grown(old.words, words):
                keep = len(old.words) - 1  # its last word may be clipped differently now
                entry.names = dict(old.names)
                tail = _word_arrays(words[keep:], value_key, entry.names)
                starts, ends, values, codes = (
                    np.concatenate((a[:keep], t)) for a, t in zip(old.arrays, tail, strict=True)
                )
                arrays = (starts, ends, values, codes)
            else:
                arrays = _word_arrays(words, value_key, entry.names)
            starts = arrays[0]
            if np.any(starts[1:] < starts[:-1]):
                entry.names = {}
                _axis_features(entry.features, prefix, words, value_key)
            else:
                entry.arrays = arrays
                _array_features(entry.features, prefix, *arrays, entry.names)
        self.entries[prefix] = entry
        return entry.features


def _same_words(a: Sequence[Word], b: Sequence[Word]) -> bool:
    n = len(a)
    if n != len(b) or a[0] != b[0] or a[-1] != b[-1]:
        return False
    return all(map(operator.is_, itertools.islice(a, 1, n - 1), itertools.islice(b, 1, n - 1)))


def _grown(a: Sequence[Word], b: Sequence[Word]) -> bool:
    """`b` is `a` with words appended (the first and last word of `a` compared by value/label)."""
    m = len(a)
    if m < 2 or len(b) < m or a[0] != b[0] or a[-1].label != b[m - 1].label:
        return False
    return all(map(operator.is_, itertools.islice(a, 1, m - 1), itertools.islice(b, 1, m - 1)))


def _axis_features_small(
    features: dict[str, float], prefix: str, words: Sequence[Word], value_key: str
) -> None:
    """_axis_features for short sequences: plain Python, one key string per label, not per word."""
    if any(b.start < a.start for a, b in itertools.pairwise(words)):
        words = sorted(words, key=lambda w: w.start)
    n = len(words)
    names = [_LABEL_NAMES.get(w.label) or _label_name(w.label) for w in words]
    spans = [w.end - w.start for w in words]
    spans = [0.0 if x < 0.0 else x for x in spans]  # = max(x, 0.0), NaN and -0.0 included
    total = sum(spans)
    weights = spans if total > 0 else [1.0] * n
    wsum = sum(weights)
    features[prefix + "n_words"] = math.log1p(n)
    fracs: dict[str, float] = {}
    for name, weight in zip(names, weights, strict=True):
        fracs[name] = fracs.get(name, 0.0) + weight / wsum
    counts = Counter(names)
    for name, frac in fracs.items():
        features[prefix + "count:" + name] = math.log1p(float(counts[name]))
        features[prefix + "frac:" + name] = frac
    for (a, b), count in Counter(itertools.pairwise(names)).items():
        features[prefix + f"bigram:{a}>{b}"] = math.log1p(float(count))
    mean = sum(w.features.get(value_key, 0.0) * wt for w, wt in zip(words, weights, strict=True))
    features[prefix + "mean_value"] = mean / wsum


def _word_arrays(
    words: Sequence[Word], value_key: str, names: dict[str, int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(starts, ends, values, label codes) of `words`; new labels get the next code in `names`."""
    n = len(words)
    starts = np.fromiter((w.start for w in words), dtype=float, count=n)
    ends = np.fromiter((w.end for w in words), dtype=float, count=n)
    values = np.fromiter((w.features.get(value_key, 0.0) for w in words), dtype=float, count=n)
    codes = np.fromiter(
        (
            names.setdefault(_LABEL_NAMES.get(w.label) or _label_name(w.label), len(names))
            for w in words
        ),
        dtype=np.intp,
        count=n,
    )
    return starts, ends, values, codes


def _axis_features(
    features: dict[str, float], prefix: str, words: Sequence[Word], value_key: str
) -> None:
    """Add the compact features of one arm/level/axis word sequence to `features` (NumPy path)."""
    names: dict[str, int] = {}
    arrays = _word_arrays(words, value_key, names)
    starts = arrays[0]
    if len(words) > 1 and np.any(starts[1:] < starts[:-1]):
        order = np.argsort(starts, kind="stable")  # = sorted(key=start), which is stable
        names = {}
        arrays = _word_arrays([words[i] for i in order], value_key, names)
    _array_features(features, prefix, *arrays, names)


def _array_features(
    features: dict[str, float],
    prefix: str,
    starts: np.ndarray,
    ends: np.ndarray,
    values: np.ndarray,
    codes: np.ndarray,
    names: dict[str, int],
) -> None:
    """_axis_features of a start-ordered sequence given as arrays."""
    n = len(starts)
    spans = np.maximum(ends - starts, 0.0)
    total = sum(spans.tolist())
    weights = spans if total > 0 else np.ones(n)
    wsum = sum(weights.tolist())
    features[prefix + "n_words"] = math.log1p(n)
    kinds = len(names)
    counts = np.bincount(codes, minlength=kinds).tolist()
    fracs = np.bincount(codes, weights=weights / wsum, minlength=kinds).tolist()
    for label, code in names.items():
        features[prefix + "count:" + label] = math.log1p(float(counts[code]))
        features[prefix + "frac:" + label] = fracs[code]
    if n > 1:
        pairs = np.bincount(codes[:-1] * kinds + codes[1:], minlength=kinds * kinds).tolist()
        labels = list(names)
        for pair in np.flatnonzero(pairs).tolist():
            a, b = labels[pair // kinds], labels[pair % kinds]
            features[prefix + f"bigram:{a}>{b}"] = math.log1p(float(pairs[pair]))
    features[prefix + "mean_value"] = sum((values * weights).tolist()) / wsum


_LABEL_NAMES: dict[str, str] = {}
"""Memo of `_label_name` (the label vocabularies are small)."""


def _label_name(label: str) -> str:
    """A word label with its alias resolved (spec 3: 'const' = 'cons')."""
    name = LABEL_ALIASES.get(label.strip(), label.strip())
    if len(_LABEL_NAMES) < 10000:
        _LABEL_NAMES[label] = name
    return name

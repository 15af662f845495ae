"""Feature encodings of sub-task samples, fitted on training data only and stored in the model.

`paper`: the resampled label-index vectors of spec 3 (one n per level = the longest label
sequence in the training data; REAL golden labels give 6204 features, SIM 1428).
`compact`: per arm, level and axis the label counts, duration fractions, label bigrams and the
duration-weighted mean value of the words, plus the log sub-task duration; features constant on
the training data are dropped, the rest are min-max scaled with bounds fixed at fit time.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import operator
import warnings
from collections import Counter
from collections.abc import Iterator, Sequence
from contextvars import ContextVar
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from sklearn.feature_selection import f_classif

from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar import ENCODINGS
from rcbht_introspection.grammar.split import SubtaskSample
from rcbht_introspection.taxonomy.words import AXES, LEVELS, Level, Word

LABEL_ALIASES: dict[str, str] = {"const": "cons"}
"""Spellings of the same label in the original files ('const' = 'cons', spec 3)."""
VALUE_KEYS: dict[Level, str] = {
    Level.PRIMITIVE: "Average",
    Level.COMPOSITION: "Average Val",
    Level.BEHAVIOR: "AVG_MAG_VAL",
}
"""The record field holding a word's mean wrench value, per level."""
NUMPY_MIN_WORDS = 128
"""Sequences at least this long get NumPy compact features (measured break-even ~120 words)."""
MIN_DURATION = 1e-3
"""Floor (s) for the log sub-task duration, so a zero-length window stays finite."""


def label_index(level: Level, label: str) -> int:
    """0-based index of `label` in its level's vocabulary (spec 3); -1 if unknown."""
    label = LABEL_ALIASES.get(label.strip(), label.strip())
    try:
        return level.labels.index(label)
    except ValueError:
        return -1


def sample_arms(samples: Sequence[SubtaskSample]) -> tuple[str, ...]:
    """Arms present in the samples (sorted), e.g. ('R',) or ('L', 'R')."""
    arms: set[str] = set()
    for sample in samples:
        arms.update(sample.words.arms)
    return tuple(sorted(arms)) or ("R",)


def label_arrays(words: Sequence[Word], level: Level) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(starts, ends, label indices) of a word sequence sorted by start time."""
    ordered = sorted(words, key=lambda w: w.start)
    starts = np.array([w.start for w in ordered], dtype=float)
    ends = np.maximum(np.array([w.end for w in ordered], dtype=float), starts)
    codes = np.array([label_index(level, w.label) for w in ordered], dtype=int)
    return starts, ends, codes


def resample_labels(words: Sequence[Word], level: Level, n: int) -> np.ndarray:
    """Spec 3 'slice_and_find_mode': n equal-duration bins, each the label covering it longest.

    Times run from the first word's start to the last word's end (words sorted by start);
    ties go to the label that appears first. An empty sequence gives -1 everywhere.
    """
    return resample_arrays(*label_arrays(words, level), n)


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
    return np.interp(edges, times, values)


class Encoding(Protocol):
    """A fitted map from samples to a fixed-length feature matrix."""

    name: str

    def fit(self, samples: Sequence[SubtaskSample]) -> Encoding: ...

    def transform(self, samples: Sequence[SubtaskSample]) -> np.ndarray: ...

    def to_state(self) -> dict[str, Any]: ...


class _SampleCache:
    """Per-sample memo of expensive intermediate results, keyed by object identity.

    Holds a reference to each sample so an id is never reused while cached. Bounded to `limit`
    results: the oldest samples go first, one at a time, so no call pays for freeing them all.
    """

    def __init__(self, limit: int = 20000) -> None:
        self.limit = limit
        self.entries: dict[int, tuple[SubtaskSample, dict[Any, Any]]] = {}
        self.size = 0

    def get(self, sample: SubtaskSample, key: Any, compute: Any) -> Any:
        hit = self.entries.get(id(sample))
        if hit is not None and hit[0] is sample and key in hit[1]:
            return hit[1][key]
        value = compute()
        if hit is None or hit[0] is not sample:
            self.forget(sample)
            while self.entries and self.size >= self.limit:
                self.size -= len(self.entries.pop(next(iter(self.entries)))[1])
            hit = self.entries[id(sample)] = (sample, {})
        hit[1][key] = value
        self.size += 1
        return value

    def forget(self, sample: SubtaskSample) -> None:
        """Drop every result of `sample` (a live window is never asked again)."""
        hit = self.entries.pop(id(sample), None)
        if hit is not None:
            self.size -= len(hit[1])


_CACHE = _SampleCache()


def forget_sample(sample: SubtaskSample) -> None:
    """Release the cached features of a sample that will not be encoded again (live windows)."""
    _CACHE.forget(sample)


@dataclass
class PaperEncoding:
    """Spec 3 vectors: per arm, level (primitive, composition, behavior) and axis, n_level bins."""

    name: str = "paper"
    arms: tuple[str, ...] = ()
    n: dict[str, int] = field(default_factory=dict)

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
        return len(self.arms) * len(AXES) * sum(self.n.values())

    def transform(self, samples: Sequence[SubtaskSample]) -> np.ndarray:
        out = np.empty((len(samples), self.n_features))
        for row, sample in enumerate(samples):
            parts = []
            for arm in self.arms:
                for level in LEVELS:
                    n = self.n[level.value]
                    for axis in AXES:
                        arrays = _CACHE.get(
                            sample,
                            ("labels", arm, level, axis),
                            lambda a=arm, lv=level, ax=axis, s=sample: label_arrays(
                                s.words.axis_words(a, lv, ax), lv
                            ),
                        )
                        parts.append(
                            _CACHE.get(
                                sample,
                                ("paper", arm, level, axis, n),
                                lambda arr=arrays, k=n: resample_arrays(*arr, k),
                            )
                        )
            out[row] = np.concatenate(parts)
        return out

    def to_state(self) -> dict[str, Any]:
        return {"name": self.name, "arms": list(self.arms), "n": dict(self.n)}


def compact_raw_features(sample: SubtaskSample, arms: Sequence[str]) -> dict[str, float]:
    """Unscaled compact features of one sample (names are 'arm/level/axis/kind:label').

    Per arm/level/axis, NumPy over long word sequences and plain Python with per-label keys over
    short ones (NumPy's fixed cost dominates there); every sum is taken in the word order of the
    plain definition (`compact_raw_features_reference`), so the floats are bit-identical to it.
    Inside `axis_memo`, unchanged axes are taken from the memo.
    """
    features: dict[str, float] = {}
    memo = _AXIS_MEMO.get()
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
                elif len(words) < NUMPY_MIN_WORDS:
                    _axis_features_small(features, prefix, words, value_key)
                else:
                    _axis_features(features, prefix, words, value_key)
    return features


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
                arrays = tuple(
                    np.concatenate((a[:keep], t)) for a, t in zip(old.arrays, tail, strict=True)
                )
            else:
                arrays = _word_arrays(words, value_key, entry.names)
            starts = arrays[0]
            if np.any(starts[1:] < starts[:-1]):
                entry.names = {}
                _axis_features(entry.features, prefix, words, value_key)
            else:
                entry.arrays = arrays  # type: ignore[assignment]
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


_AXIS_MEMO: ContextVar[AxisMemo | None] = ContextVar("axis_memo", default=None)


@contextlib.contextmanager
def axis_memo(memo: AxisMemo) -> Iterator[None]:
    """Within the block, compact_raw_features reuses and updates `memo` (one live stream's)."""
    token = _AXIS_MEMO.set(memo)
    try:
        yield
    finally:
        _AXIS_MEMO.reset(token)


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
    """Add the compact features of one arm/level/axis word sequence to `features`."""
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


def compact_raw_features_reference(sample: SubtaskSample, arms: Sequence[str]) -> dict[str, float]:
    """The plain per-word definition of `compact_raw_features` (kept as its test oracle)."""
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


def pairwise_selection(matrix: np.ndarray, labels: Sequence[str], k: int) -> np.ndarray:
    """Indices of k columns taken in turn from each pair of classes' ANOVA F ranking.

    A single multi-class F ranking is dominated by the easiest contrast (e.g. the 5 ms rotation
    samples against everything); ranking per class pair keeps features for every contrast.
    """
    labels_arr = np.asarray(labels)
    classes = sorted(set(labels))
    rankings = []
    for i, a in enumerate(classes):
        for b in classes[i + 1 :]:
            rows = (labels_arr == a) | (labels_arr == b)
            with np.errstate(divide="ignore", invalid="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore")
                scores, _ = f_classif(matrix[rows], labels_arr[rows])
            scores = np.nan_to_num(scores, nan=0.0, posinf=np.finfo(float).max)
            rankings.append(np.argsort(-scores, kind="stable"))
    chosen: list[int] = []
    seen: set[int] = set()
    depth = 0
    while len(chosen) < min(k, matrix.shape[1]):
        for ranking in rankings:
            column = int(ranking[depth])
            if column not in seen and len(chosen) < k:
                seen.add(column)
                chosen.append(column)
        depth += 1
    return np.asarray(sorted(chosen), dtype=int)


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

    def _raw(self, sample: SubtaskSample) -> dict[str, float]:
        return _CACHE.get(
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
        return len(self.feature_names)

    def transform(self, samples: Sequence[SubtaskSample]) -> np.ndarray:
        lower, scale = np.asarray(self.lower), np.asarray(self.scale)
        out = np.empty((len(samples), self.n_features))
        for row, sample in enumerate(samples):
            raw = self._raw(sample)
            out[row] = [raw.get(k, 0.0) for k in self.feature_names]
        return (out - lower) / scale

    def to_state(self) -> dict[str, Any]:
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


def make_encoding(name: str) -> PaperEncoding | CompactEncoding:
    """A fresh (unfitted) encoding by name."""
    if name == "paper":
        return PaperEncoding()
    if name == "compact":
        return CompactEncoding()
    raise InputError(f"unknown encoding {name!r} (known: {', '.join(ENCODINGS)})")


def encoding_from_state(state: dict[str, Any]) -> PaperEncoding | CompactEncoding:
    """Rebuild a fitted encoding from its stored parameters; bad fields are one-line errors."""
    try:
        name = state["name"]
        if name == "paper":
            n = {str(k): int(v) for k, v in state["n"].items()}
            if set(n) != {lv.value for lv in LEVELS}:
                raise ValueError("n must name every level")
            return PaperEncoding(arms=tuple(map(str, state["arms"])), n=n)
        if name == "compact":
            enc = CompactEncoding(
                values=bool(state["values"]),
                bigrams=bool(state["bigrams"]),
                k=None if state["k"] is None else int(state["k"]),
                arms=tuple(map(str, state["arms"])),
                feature_names=[str(x) for x in state["feature_names"]],
                lower=[float(x) for x in state["lower"]],
                scale=[float(x) for x in state["scale"]],
            )
            if not (len(enc.feature_names) == len(enc.lower) == len(enc.scale)):
                raise ValueError("feature_names, lower and scale differ in length")
            return enc
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise InputError(f"bad encoding parameters: {exc}", field="encoding") from None
    raise InputError(f"unknown encoding {state.get('name')!r}", field="encoding.name")

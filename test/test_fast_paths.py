"""The fast feature, window and SVM paths equal their plain definitions bit for bit.

On real words (golden sub-tasks and live windows of a streamed REAL trial), on the engine's words
of simulated trials (made at test time) and on generated word sequences (unsorted, zero-length,
aliased and unknown labels).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import SOURCES, golden_or_engine, trial_folders
from hypothesis import given, settings
from hypothesis import strategies as st
from references import compact_raw_features_reference

from rcbht_introspection.grammar.encoding.axes import (
    NUMPY_MIN_WORDS,
    AxisMemo,
    _axis_features,
    _axis_features_small,
)
from rcbht_introspection.grammar.encoding.cache import SampleCache as _SampleCache
from rcbht_introspection.grammar.encoding.compact import (
    VALUE_KEYS,
    compact_raw_features,
)
from rcbht_introspection.grammar.split import SubtaskSample, window_sample
from rcbht_introspection.io.hiro import read_trial
from rcbht_introspection.learn.data import load_trials
from rcbht_introspection.learn.live import LiveAugmentConfig, stream_factory
from rcbht_introspection.learn.models import train_model
from rcbht_introspection.learn.svm import svm_predict_proba
from rcbht_introspection.live.replay import stream_trial
from rcbht_introspection.taxonomy.words import AXES, LEVELS, Level, TrialWords, Word

TRIALS = ("20121127-HIROSA-S-01", "20121127-HIROSA-S-45")


def _trials(request: pytest.FixtureRequest, source: str) -> list[Path]:
    """REAL S-01 and S-45, or the first two generated trials."""
    return trial_folders(request, source, TRIALS, [0, 1])


def _samples(request: pytest.FixtureRequest, source: str) -> list[SubtaskSample]:
    """Sub-task samples of both trials: golden words (HIRO) or the batch engine's (generated)."""
    trials = load_trials(_trials(request, source), golden_or_engine(source))
    return [s for t in trials for s in t.samples]


def _same(a: dict[str, float], b: dict[str, float]) -> bool:
    """Same keys and bit-identical values (repr distinguishes every float, NaN included)."""
    return a.keys() == b.keys() and all(repr(a[k]) == repr(b[k]) for k in a)


@pytest.mark.parametrize("source", SOURCES)
def test_fast_features_equal_reference_on_trial_subtasks(
    request: pytest.FixtureRequest, source: str
) -> None:
    samples = _samples(request, source)
    assert len(samples) >= 8
    for sample in samples:
        assert _same(
            compact_raw_features(sample, ["R"]), compact_raw_features_reference(sample, ["R"])
        )


@pytest.mark.parametrize("source", SOURCES)
def test_fast_windows_and_features_equal_reference_on_live_words(
    request: pytest.FixtureRequest, source: str
) -> None:
    """Live windows of a streamed trial: bisected window == scanned window, fast == plain features."""
    streamed = stream_trial(
        read_trial(_trials(request, source)[1]), stream_factory(LiveAugmentConfig())
    )
    words = TrialWords(name=streamed.name)
    checked = 0
    for i, (t, w) in enumerate(streamed.released()):
        words.add(w)
        if i % 25:
            continue
        for start in (max(0.0, t - 2.0), t / 2, 0.0, t):
            fast = window_sample(words, start, t, ordered=True)
            plain = window_sample(words, start, t)
            assert fast.words == plain.words
            assert _same(
                compact_raw_features(fast, ["R"]), compact_raw_features_reference(plain, ["R"])
            )
            checked += 1
    assert checked > 100


_LABELS = st.sampled_from(["pos", "neg", "cons", "const", " const ", "a", "k", "weird"])


@pytest.mark.parametrize("source", SOURCES)
def test_axis_memo_gives_the_fresh_features_of_every_running_window(
    request: pytest.FixtureRequest, source: str
) -> None:
    """Growing boundary windows and sliding 2 s windows of a streamed trial, after every word."""
    streamed = stream_trial(
        read_trial(_trials(request, source)[1]), stream_factory(LiveAugmentConfig())
    )
    words = TrialWords(name=streamed.name)
    memos = {"boundary": AxisMemo(), "window": AxisMemo()}
    longest = 0
    for i, (t, w) in enumerate(streamed.released()):
        words.add(w)
        for mode, start in (("boundary", 0.0 if t < 20 else 20.0), ("window", max(0.0, t - 2.0))):
            sample = window_sample(words, start, t, ordered=True)
            memoised = compact_raw_features(sample, ["R"], memos[mode])
            assert _same(memoised, compact_raw_features(sample, ["R"])), (i, mode)
        longest = max(longest, *(len(e.words) for e in memos["boundary"].entries.values()))
    assert longest >= 2 * NUMPY_MIN_WORDS  # the long sequences grew through the array path


@st.composite
def _growing_axis(draw: st.DrawFn) -> list[list[Word]]:
    """Successive views of one axis: words appended, the last and first word clipped anew."""
    n = draw(st.integers(1, 3 * NUMPY_MIN_WORDS))
    labels = draw(st.lists(_LABELS, min_size=n, max_size=n))
    starts = np.cumsum(draw(st.lists(st.sampled_from([0.0, 0.1, 0.25]), min_size=n, max_size=n)))
    full = [
        Word(
            axis="Fz",
            level=Level.PRIMITIVE,
            label=lab,
            start=float(s),
            end=float(s) + 0.3,
            features={"Average": float(k % 7)},
        )
        for k, (lab, s) in enumerate(zip(labels, starts, strict=True))
    ]
    views = []
    for cut in sorted(draw(st.lists(st.integers(1, n), min_size=1, max_size=6))):
        view = list(full[:cut])
        if draw(st.booleans()):  # a window end inside the last word
            view[-1] = replace(view[-1], end=view[-1].start + draw(st.sampled_from([0.0, 0.1])))
        if draw(st.booleans()) and len(view) > 1:  # a window start inside the first word
            view[0] = replace(view[0], start=view[0].start + 0.05)
        if draw(st.booleans()) and len(view) > 2:  # a late word out of start order
            view.append(replace(view[-2], start=view[-2].start - 0.01))
        views.append(view)
    return views


@settings(max_examples=150, deadline=None)
@given(_growing_axis())
def test_axis_memo_gives_the_fresh_features_of_generated_views(views: list[list[Word]]) -> None:
    memo = AxisMemo()
    for view in views:
        fresh: dict[str, float] = {}
        if len(view) < NUMPY_MIN_WORDS:
            _axis_features_small(fresh, "R/p/Fz/", view, "Average")
        else:
            _axis_features(fresh, "R/p/Fz/", view, "Average")
        assert _same(memo.features("R/p/Fz/", view, "Average"), fresh)


@st.composite
def _axis_words(draw: st.DrawFn) -> list[Word]:
    spans = draw(
        st.lists(
            st.tuples(st.floats(0, 10), st.floats(-1, 3), _LABELS, st.floats(-5, 5)), max_size=12
        )
    )
    return [
        Word(
            axis="Fz",
            level=Level.COMPOSITION,
            label=label,
            start=s,
            end=s + d,
            features={"Average Val": v},
        )
        for s, d, label, v in spans
    ]


@settings(max_examples=200, deadline=None)
@given(_axis_words(), st.floats(0, 20))
def test_fast_features_equal_reference_on_generated_words(
    words: list[Word], duration: float
) -> None:
    tw = TrialWords(name="t")
    for w in words:
        tw.add(w)
    sample = SubtaskSample("t", "approach", 0.0, duration, tw)
    assert _same(compact_raw_features(sample, ["R"]), compact_raw_features_reference(sample, ["R"]))


@pytest.mark.parametrize("source", SOURCES)
def test_svm_fast_probabilities_equal_checked_pipeline(
    request: pytest.FixtureRequest, source: str
) -> None:
    """svm_predict_proba == Pipeline.predict_proba bit for bit; bad input still raises."""
    samples = _samples(request, source)
    model = train_model(samples, "svm", running_prefixes=())
    X = model.features(samples)
    assert np.array_equal(svm_predict_proba(model.estimator, X), model.estimator.predict_proba(X))
    for row in X:
        one = row[None, :]
        assert np.array_equal(
            svm_predict_proba(model.estimator, one), model.estimator.predict_proba(one)
        )
    bad = X[:1].copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError):
        svm_predict_proba(model.estimator, bad)
    with pytest.raises(ValueError):
        svm_predict_proba(model.estimator, X[:, :-1])


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.tuples(st.sampled_from([0.0, 0.5, 1.0]), st.sampled_from([0.0, 0.5, 1.5])), max_size=10
    ),
    st.sampled_from([0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.5]),
    st.sampled_from([0.0, 0.5, 1.0, 2.0, 2.5, 4.0, 9.0]),
)
def test_bisected_window_equals_scanned_window(
    steps: list[tuple[float, float]], start: float, end: float
) -> None:
    """Touching, overlapping and zero-length words, windows on and between their bounds."""
    tw = TrialWords(name="t")
    t = last_end = 0.0
    for gap, length in steps:  # non-decreasing starts and ends, as a live stream gives
        t += gap
        last_end = max(last_end, t + length)
        tw.add(Word(axis="Fz", level=Level.PRIMITIVE, label="pos", start=t, end=last_end))
    assert window_sample(tw, start, end, ordered=True).words == window_sample(tw, start, end).words


@pytest.mark.parametrize("source", SOURCES)
def test_both_axis_paths_equal_reference_on_trial_axes(
    request: pytest.FixtureRequest, source: str
) -> None:
    """The NumPy and the short-sequence path each equal the plain definition on every trial axis."""
    samples = _samples(request, source)
    longest = 0
    for sample in samples:
        for level in LEVELS:
            for axis in AXES:
                words = sample.words.axis_words("R", level, axis)
                if not words:
                    continue
                longest = max(longest, len(words))
                one = SubtaskSample(
                    "t", "approach", 0.0, 1.0, TrialWords("t", {"R": {level: {axis: words}}})
                )
                expected = compact_raw_features_reference(one, ["R"])
                for path in (_axis_features, _axis_features_small):
                    got = {"log_duration": expected["log_duration"]}
                    path(got, f"R/{level.value}/{axis}/", words, VALUE_KEYS[level])
                    assert _same(got, expected)
    assert longest >= NUMPY_MIN_WORDS


def test_sample_cache_evicts_oldest_samples_and_forgets() -> None:
    """Bounded by results, oldest sample first; forget drops a sample; hits do not recompute."""
    cache = _SampleCache(limit=3)
    a, b, c = (SubtaskSample("t", "approach", 0.0, float(i), TrialWords("t")) for i in range(3))
    calls: list[str] = []

    def compute(tag: str) -> str:
        calls.append(tag)
        return tag

    assert cache.get(a, 1, lambda: compute("a1")) == "a1"
    assert cache.get(a, 2, lambda: compute("a2")) == "a2"
    assert cache.get(b, 1, lambda: compute("b1")) == "b1"
    assert cache.get(a, 1, lambda: compute("x")) == "a1"  # hit
    assert cache.get(c, 1, lambda: compute("c1")) == "c1"  # full: a (2 results) goes
    assert cache.size == 2 and set(cache.entries) == {id(b), id(c)}
    cache.forget(b)
    assert cache.size == 1 and set(cache.entries) == {id(c)}
    assert cache.get(a, 1, lambda: compute("a1")) == "a1"
    assert calls == ["a1", "a2", "b1", "c1", "a1"]

"""Property tests: any signal gives time-ordered words that cover it, and never a crash."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from rcbht_introspection.taxonomy.batch import label_arm
from rcbht_introspection.taxonomy.config import default_config
from rcbht_introspection.taxonomy.words import AXES, LEVELS, Level, TrialWords

DT = 0.005
finite = st.floats(min_value=-1e4, max_value=1e4, allow_nan=False, allow_infinity=False)


def shaped(kind: str, n: int, value: float, at: int) -> np.ndarray:
    """Hand-shaped signals: flat (zeros), constant, step, impulse."""
    y = np.zeros((n, 6))
    if kind == "constant":
        y[:] = value
    elif kind == "step":
        y[at:] = value
    elif kind == "impulse" and n:
        y[at] = value
    return y


@st.composite
def signals(draw: st.DrawFn) -> tuple[np.ndarray, tuple[float, ...]]:
    kind = draw(st.sampled_from(["random", "walk", "flat", "constant", "step", "impulse", "short"]))
    n = draw(st.integers(0, 4)) if kind == "short" else draw(st.integers(0, 400))
    if kind in ("random", "short"):
        y = draw(arrays(np.float64, (n, 6), elements=finite))
    elif kind == "walk":
        steps = draw(arrays(np.float64, (n, 6), elements=st.floats(-50, 50)))
        y = np.cumsum(steps, axis=0)
    else:
        value = draw(finite)
        y = shaped(kind, n, value, draw(st.integers(0, max(n - 1, 0))))
    end = (n - 1) * DT if n else 0.0
    cuts = sorted(draw(st.lists(st.floats(0, max(end, 0.0)), max_size=3)))
    return y, (0.0, *cuts)


def check_words(words: TrialWords, n: int) -> None:
    end = (n - 1) * DT
    for level in LEVELS:
        for axis in AXES:
            seq = words.axis_words("R", level, axis)
            if n < 2:
                assert seq == []
                continue
            assert seq, (level, axis)
            starts = [w.start for w in seq]
            assert starts == sorted(starts), (level, axis)
            assert seq[0].start == 0.0
            assert seq[-1].end >= end - 1e-9
            assert all(w.end >= w.start for w in seq)
            assert all(w.label in level.labels for w in seq)
            if level is Level.PRIMITIVE:  # consecutive segments share their boundary sample
                for a, b in itertools.pairwise(seq):
                    assert a.end == pytest.approx(b.start) or a.end == pytest.approx(
                        b.start * 21 / 20
                    )


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(signals())
def test_any_signal_gives_ordered_covering_words(
    signal: tuple[np.ndarray, tuple[float, ...]],
) -> None:
    y, states = signal
    t = np.arange(len(y)) * DT
    words = label_arm(t, y, states, default_config(), "R", TrialWords("prop"))
    check_words(words, len(y))


@pytest.mark.parametrize("n", [0, 1, 2, 3, 4, 5, 6, 7, 11, 12])
@pytest.mark.parametrize("kind", ["flat", "constant", "step", "impulse"])
def test_shaped_and_tiny_signals(kind: str, n: int) -> None:
    y = shaped(kind, n, 7.5, n // 2)
    t = np.arange(n) * DT
    words = label_arm(t, y, (0.0, 0.01, 0.02, 0.03), default_config(), "R", TrialWords("x"))
    check_words(words, n)

"""Encodings: spec-3 resampling on hand-checkable sequences, the paper's dimensions on the
golden labels and on generated trials, and compact features fitted on training samples only."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import SIM_SUCCESS
from references import resample_labels

from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar.encoding.compact import CompactEncoding
from rcbht_introspection.grammar.encoding.paper import PaperEncoding
from rcbht_introspection.grammar.encoding.registry import encoding_from_state
from rcbht_introspection.grammar.split import SubtaskSample
from rcbht_introspection.learn.data import load_trials
from rcbht_introspection.taxonomy.words import AXES, LEVELS, Level, TrialWords, Word


def _w(
    label: str, start: float, end: float, level: Level = Level.COMPOSITION, axis: str = "Fx"
) -> Word:
    return Word(
        axis=axis, level=level, label=label, start=start, end=end, features={"Average Val": 1.0}
    )


def test_resample_is_a_duration_weighted_mode_per_bin() -> None:
    # 'a' covers [0, 3), 'k' [3, 4): with 4 bins each bin is one second
    words = [_w("a", 0.0, 3.0), _w("k", 3.0, 4.0)]
    assert resample_labels(words, Level.COMPOSITION, 4).tolist() == [0, 0, 0, 3]
    # 2 bins of 2 s: bin 2 holds 1 s of 'a' and 1 s of 'k': a tie goes to the first label
    assert resample_labels(words, Level.COMPOSITION, 2).tolist() == [0, 0]
    # times are relative to the first label's start; 'const' is 'cons' (index 6)
    shifted = [_w("const", 10.0, 11.0, Level.PRIMITIVE), _w("spos", 11.0, 14.0, Level.PRIMITIVE)]
    assert resample_labels(shifted, Level.PRIMITIVE, 4).tolist() == [6, 2, 2, 2]
    assert resample_labels([], Level.BEHAVIOR, 3).tolist() == [-1, -1, -1]


def test_zero_length_sequence_gets_its_first_label() -> None:
    assert resample_labels([_w("d", 5.0, 5.0)], Level.COMPOSITION, 3).tolist() == [2, 2, 2]


@pytest.mark.shared_data
@pytest.mark.parametrize(("dataset", "dims", "n"), [
    ("REAL_HIRO_ONE_SA_SUCCESS", 6204, {"primitive": 844, "composition": 161, "behavior": 29}),
    ("SIM_HIRO_ONE_SA_SUCCESS", 1428, {"primitive": 179, "composition": 37, "behavior": 22}),
])  # fmt: skip
def test_paper_dimensions_from_golden_labels(
    hiro_data: Path, dataset: str, dims: int, n: dict
) -> None:
    trials = [t for t in load_trials([hiro_data / dataset], "golden") if t.complete]
    samples = [s for t in trials for s in t.samples]
    encoding = PaperEncoding().fit(samples)
    assert encoding.n == n
    assert encoding.n_features == dims
    X = encoding.transform(samples[:8])
    assert X.shape == (8, dims) and X.min() >= -1 and X.max() <= 9


def test_paper_dimensions_from_engine_words(sim_data: Path) -> None:
    """On the engine's words of generated trials, n per level is the longest label sequence of
    any sample and axis, and each vector holds 6 * sum(n) label indices (-1: no label)."""
    samples = [s for t in load_trials([sim_data / SIM_SUCCESS], "engine") for s in t.samples]
    encoding = PaperEncoding().fit(samples)
    longest = {
        level.value: max(
            len(s.words.axis_words("R", level, axis)) for s in samples for axis in AXES
        )
        for level in LEVELS
    }
    assert encoding.n == longest and min(longest.values()) > 1
    assert encoding.n_features == len(AXES) * sum(longest.values())
    X = encoding.transform(samples)
    assert X.shape == (len(samples), encoding.n_features) and X.min() >= -1 and X.max() <= 9


def _sample(subtask: str, duration: float, labels: list[str]) -> SubtaskSample:
    tw = TrialWords(name="t")
    step = duration / len(labels)
    for i, label in enumerate(labels):
        tw.add(_w(label, i * step, (i + 1) * step))
    return SubtaskSample("t", subtask, 0.0, duration, tw)


def test_compact_bounds_come_from_training_samples_only() -> None:
    train = [_sample("approach", 4.0, ["a", "k"]), _sample("mating", 0.005, ["k"]),
             _sample("approach", 5.0, ["a", "k", "k"]), _sample("mating", 0.01, ["k"])]  # fmt: skip
    encoding = CompactEncoding(k=None).fit(train)
    state = encoding.to_state()
    X_train = encoding.transform(train)
    assert X_train.min() == pytest.approx(0.0) and X_train.max() == pytest.approx(1.0)
    # a far-away validation sample changes nothing in the fitted parameters
    far = _sample("approach", 60.0, ["i", "i", "d", "k"])
    x_far = encoding.transform([far])
    assert encoding.to_state() == state
    assert x_far[0, encoding.feature_names.index("log_duration")] > 1.0
    # the near-empty samples are told apart by the log duration alone
    column = X_train[:, encoding.feature_names.index("log_duration")]
    assert column[1] < 0.2 and column[3] < 0.2 and column[0] > 0.8


def test_compact_state_round_trip_and_bad_state() -> None:
    train = [_sample("approach", 4.0, ["a", "k"]), _sample("mating", 0.5, ["k", "d"])]
    encoding = CompactEncoding().fit(train)
    again = encoding_from_state(encoding.to_state())
    np.testing.assert_array_equal(again.transform(train), encoding.transform(train))
    with pytest.raises(InputError, match="encoding"):
        encoding_from_state({"name": "compact", "arms": ["R"]})
    with pytest.raises(InputError, match="unknown encoding"):
        encoding_from_state({"name": "fourier"})


def test_two_arm_samples_concatenate_both_arms() -> None:
    def two_arm(subtask: str, duration: float, left: str, right: str) -> SubtaskSample:
        tw = TrialWords(name="t")
        for arm, label in (("L", left), ("R", right)):
            tw.add(
                Word(axis="Fz", level=Level.BEHAVIOR, label=label, start=0.0, end=duration, arm=arm)
            )
        return SubtaskSample("t", subtask, 0.0, duration, tw)

    train = [two_arm("approach", 2.0, "FX", "CT"), two_arm("mating", 3.0, "CT", "FX")]
    paper = PaperEncoding().fit(train)
    assert paper.arms == ("L", "R") and paper.n_features == 2 * 6 * 3
    X = paper.transform(train)
    fz_behavior = [i for i in range(X.shape[1]) if (i % (6 * 3)) == 2 * 6 + 2]  # level 2, axis Fz
    assert X[0, fz_behavior].tolist() == [0, 1] and X[1, fz_behavior].tolist() == [1, 0]
    compact = CompactEncoding(k=None).fit(train)
    assert {"L/behavior/Fz/frac:FX", "R/behavior/Fz/frac:FX"} <= set(compact.feature_names)

"""Sub-task split (spec 2.7) and live windows: boundary-spanning words are cut, nothing is lost."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import SIM_SUCCESS

from rcbht_introspection.grammar.split import SubtaskSample, split_words, window_sample
from rcbht_introspection.io.hiro import find_trials, read_state_times, read_trial
from rcbht_introspection.io.rcbht_format import read_trial_words
from rcbht_introspection.io.trial import SUBTASKS
from rcbht_introspection.taxonomy.words import AXES, LEVELS, Level, TrialWords, Word


def _words(spans: list[tuple[str, float, float]], arm: str = "R") -> TrialWords:
    tw = TrialWords(name="t")
    for label, start, end in spans:
        tw.add(Word(axis="Fx", level=Level.COMPOSITION, label=label, start=start, end=end, arm=arm))
    return tw


def _spans(sample, arm: str = "R") -> list[tuple[str, float, float]]:
    return [
        (w.label, w.start, w.end) for w in sample.words.axis_words(arm, Level.COMPOSITION, "Fx")
    ]


def test_word_spanning_two_marks_is_cut_into_three() -> None:
    tw = _words([("a", 0.0, 1.0), ("k", 1.0, 3.5), ("d", 3.5, 4.0)])
    parts = split_words(tw, (0.0, 2.0, 3.0, 3.8), 4.0)
    assert [p.subtask for p in parts] == ["approach", "rotation", "insertion", "mating"]
    assert _spans(parts[0]) == [("a", 0.0, 1.0), ("k", 1.0, 2.0)]
    assert _spans(parts[1]) == [("k", 2.0, 3.0)]
    assert _spans(parts[2]) == [("k", 3.0, 3.5), ("d", 3.5, 3.8)]
    assert _spans(parts[3]) == [("d", 3.8, 4.0)]


def test_word_ending_on_a_mark_closes_the_subtask() -> None:
    parts = split_words(_words([("a", 0.0, 2.0), ("i", 2.0, 4.0)]), (0.0, 2.0), 4.0)
    assert _spans(parts[0]) == [("a", 0.0, 2.0)]
    assert _spans(parts[1]) == [("i", 2.0, 4.0)]


def test_two_arms_are_split_alike() -> None:
    tw = _words([("a", 0.0, 4.0)], arm="L")
    for w in _words([("k", 0.0, 4.0)], arm="R").axis_words("R", Level.COMPOSITION, "Fx"):
        tw.add(w)
    parts = split_words(tw, (0.0, 1.0), 4.0)
    assert _spans(parts[0], "L") == [("a", 0.0, 1.0)] and _spans(parts[0], "R") == [("k", 0.0, 1.0)]
    assert _spans(parts[1], "L") == [("a", 1.0, 4.0)] and _spans(parts[1], "R") == [("k", 1.0, 4.0)]


def test_window_keeps_overlapping_words_clipped_and_zero_length_window() -> None:
    tw = _words([("a", 0.0, 1.0), ("k", 1.0, 3.0), ("d", 3.0, 4.0)])
    assert _spans(window_sample(tw, 0.5, 2.0)) == [("a", 0.5, 1.0), ("k", 1.0, 2.0)]
    assert _spans(window_sample(tw, 2.0, 2.0)) == [("k", 2.0, 2.0)]


def _assert_conserved(words: TrialWords, parts: list[SubtaskSample]) -> None:
    """Every level/axis keeps its total time, and no word is lost (cut words count more)."""
    for level in LEVELS:
        for axis in AXES:
            original = words.axis_words("R", level, axis)
            pieces = [w for p in parts for w in p.words.axis_words("R", level, axis)]
            assert len(pieces) >= len(original)
            total = sum(w.end - w.start for w in original)
            assert sum(w.end - w.start for w in pieces) == pytest.approx(total, abs=1e-9)


@pytest.mark.shared_data
def test_golden_split_conserves_duration_and_count(hiro_data: Path) -> None:
    """On a REAL trial with a 5 ms rotation, every level/axis keeps its total time, and the
    rotation sub-task is not empty."""
    trial = hiro_data / "REAL_HIRO_ONE_SA_SUCCESS" / "20121127-HIROSA-S-30"
    words = read_trial_words(trial / "golden", levels=LEVELS)
    state = read_state_times(trial / "R_State.dat", strict=True).times
    end = max(w.end for w in words.axis_words("R", Level.BEHAVIOR, "Fx"))
    parts = split_words(words, state, end)
    assert len(parts) == 4 and parts[1].duration == pytest.approx(0.005)
    _assert_conserved(words, parts)
    for level in LEVELS:
        for axis in AXES:
            assert parts[1].words.axis_words("R", level, axis), (level, axis)


def test_engine_split_conserves_duration_and_count(sim_data: Path) -> None:
    """On the engine's words of a simulated trial, split at its state times, every level/axis
    keeps its total time, and the split covers the trial from the first mark to the end."""
    from rcbht_introspection.taxonomy.batch import label_trial

    trial = read_trial(find_trials([sim_data / SIM_SUCCESS])[0])
    words = label_trial(trial)
    parts = split_words(words, trial.state_times, trial.end_time)
    assert [p.subtask for p in parts] == list(SUBTASKS)
    assert [(p.start, p.end) for p in parts] == list(
        zip(trial.state_times, [*trial.state_times[1:], trial.end_time], strict=True)
    )
    _assert_conserved(words, parts)

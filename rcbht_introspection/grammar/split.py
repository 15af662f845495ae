"""Sub-task split of a trial's words by its state times (spec 2.7), and live time windows.

A word that spans a sub-task boundary is cut there: the part before the mark stays in the
earlier sub-task and the rest is re-examined for the next one, as data_folder_parser.py does.
"""

from __future__ import annotations

from bisect import bisect_left, bisect_right
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

from rcbht_introspection.io.trial import SUBTASKS
from rcbht_introspection.summaries.blocks import WrenchTrack
from rcbht_introspection.taxonomy.words import TrialWords, Word


@dataclass
class SubtaskSample:
    """The words of one sub-task of one trial (every arm, level and axis), clipped to [start, end]."""

    trial: str
    subtask: str
    start: float
    end: float
    words: TrialWords
    wrench: Mapping[str, WrenchTrack] = field(default_factory=dict)
    """Each arm's wrench block means (summaries/blocks.py); the sample reads those of
    [start, end] and the block before it. Empty: words only."""

    @property
    def duration(self) -> float:
        return self.end - self.start


def _clip(word: Word, start: float | None = None, end: float | None = None) -> Word:
    """A copy of `word` with its span limited to [start, end] (None keeps that side)."""
    new_start = word.start if start is None else max(word.start, start)
    new_end = word.end if end is None else min(word.end, end)
    if new_start == word.start and new_end == word.end:
        return word
    return replace(word, start=new_start, end=new_end)


def _deal_sequence(
    sequence: Sequence[Word], marks: Sequence[float], parts: list[TrialWords]
) -> None:
    """Deal one axis's words, in order, to the sub-task parts: a word ending before the next
    mark stays, one ending at it closes the part, one crossing it is cut in two."""
    state = 0
    for word in sequence:
        current = word
        while True:
            mark = marks[state]
            if current.end < mark:
                parts[state].add(current)
                break
            if current.end == mark:
                parts[state].add(current)
                state += 1
                break
            parts[state].add(_clip(current, end=mark))
            state += 1
            if state >= len(marks):
                break
            current = _clip(current, start=mark)
        if state >= len(marks):
            break


def split_words(
    words: TrialWords,
    state_times: Sequence[float],
    end_time: float,
    names: Sequence[str] = SUBTASKS,
    wrench: Mapping[str, WrenchTrack] | None = None,
) -> list[SubtaskSample]:
    """One SubtaskSample per sub-task that has a start time; the last ends at `end_time`.

    For each arm/level/axis the words are walked in order against the marks (the state times
    after the first, then `end_time`): a word ending before a mark stays in the current
    sub-task, one ending at it closes the sub-task, one crossing it is cut in two. Words past
    `end_time` are clipped to it; `names` names the sub-task of each state time (state times
    beyond it are ignored; a repeated name gives another sample of that sub-task). `wrench`:
    the trial's block means, shared by its samples.
    """
    starts = [float(t) for t in list(state_times)[: len(names)]]
    if not starts:
        return []
    marks = [*starts[1:], float(end_time)]
    parts = [TrialWords(name=words.name) for _ in starts]
    for arm, per_level in words.words.items():
        for level, per_axis in per_level.items():
            for axis, sequence in per_axis.items():
                # keep every (arm, level, axis) key present in every part, even if empty
                for part in parts:
                    part.words.setdefault(arm, {}).setdefault(level, {}).setdefault(axis, [])
                _deal_sequence(sequence, marks, parts)
    return [
        SubtaskSample(words.name, names[i], starts[i], marks[i], parts[i], wrench or {})
        for i in range(len(starts))
    ]


def window_sample(
    words: TrialWords,
    start: float,
    end: float,
    subtask: str = "",
    trial: str | None = None,
    ordered: bool = False,
    wrench: Mapping[str, WrenchTrack] | None = None,
) -> SubtaskSample:
    """The words overlapping [start, end], clipped to it (a live or prefix view of a sub-task).

    A word overlaps when it ends after `start` and starts before `end`; a zero-length window
    keeps the words that contain its instant, so a 5 ms sub-task is never empty. `ordered`
    promises that every sequence's starts and ends are non-decreasing (a live word stream):
    then only the candidate range found by bisection is examined, with the same rule.
    `wrench`: the stream's block means (the sample reads those of its window).
    """
    out = TrialWords(name=words.name)
    ordered = ordered and start <= end
    for arm, per_level in words.words.items():
        for level, per_axis in per_level.items():
            for axis, sequence in per_axis.items():
                target = out.words.setdefault(arm, {}).setdefault(level, {}).setdefault(axis, [])
                if ordered:
                    _ordered_window(sequence, start, end, target)
                    continue
                for word in sequence:
                    if word.end < start or word.start > end:
                        continue
                    if word.end == start and word.start < start:
                        continue
                    target.append(_clip(word, start, end))
    name = words.name if trial is None else trial
    return SubtaskSample(name, subtask, start, end, out, wrench or {})


def _ordered_window(sequence: list[Word], start: float, end: float, target: list[Word]) -> None:
    """window_sample's rule on a sequence with non-decreasing starts and ends, in O(log n + edges).

    Candidates lie between the first word ending at/after `start` and the last starting at/before
    `end`; only a prefix (starting before `start`) and a suffix (ending after `end`) can be
    dropped or clipped, the words between are taken unchanged as one slice.
    """
    lo = bisect_left(sequence, start, key=_word_end)
    hi = bisect_right(sequence, end, lo=lo, key=_word_start)
    while lo < hi and sequence[lo].start < start:
        word = sequence[lo]
        if not (word.end < start or word.end == start):
            target.append(_clip(word, start, end))
        lo += 1
    tail: list[Word] = []
    while hi > lo and sequence[hi - 1].end > end:
        tail.append(_clip(sequence[hi - 1], start, end))
        hi -= 1
    target.extend(sequence[lo:hi])
    target.extend(reversed(tail))


def _word_start(word: Word) -> float:
    return word.start


def _word_end(word: Word) -> float:
    return word.end


def prefix_sample(sample: SubtaskSample, fraction: float) -> SubtaskSample:
    """The first `fraction` of a sub-task's time: what a live classifier has seen so far."""
    end = sample.start + fraction * sample.duration
    return window_sample(
        sample.words, sample.start, end, sample.subtask, sample.trial, wrench=sample.wrench
    )

"""Offline references and scores for live replays: what the nodes should have produced.

`offline_stream_words` feeds a trial to ArmStream exactly as segmenter_node is fed by a replayed
trial bag (sample by sample, each /task_phase event applied at the last sample before it, the end
event finishing the stream), so node words can be compared word for word. The scores take the
/task_state timeline and the final sub-task verdicts received from the nodes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from rcbht_introspection.grammar.split import split_words
from rcbht_introspection.io.bags import trial_phase_events
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.summaries.blocks import trial_tracks
from rcbht_introspection.taxonomy.words import TrialWords, Word

if TYPE_CHECKING:
    from rcbht_introspection.live.belief import SampleClassifier
    from rcbht_introspection.taxonomy.stream import ArmStream


def offline_stream_words(
    trial: Trial, stream_factory: Callable[[str], ArmStream], end_phase: str = "done"
) -> dict[str, list[Word]]:
    """Words per arm, in emission order, of ArmStream fed the trial as the segmenter node is."""
    out: dict[str, list[Word]] = {}
    events = trial_phase_events(trial, end_phase)
    for arm in trial.arms:
        stream = stream_factory(arm)
        words: list[Word] = []
        wrench = trial.wrench[arm]
        # stream time as the node computes it from integer-nanosecond stamps
        ns = np.rint(np.asarray(trial.time, dtype=float) * 1e9).astype(np.int64)
        event_ns = [round(e * 1e9) for e, _ in events]
        ev = 0
        finished = False
        for i in range(len(ns)):
            t = (int(ns[i]) - int(ns[0])) / 1e9
            words.extend(stream.push(t, wrench[i]))
            # events before the next sample apply at this one (the bag plays them right after it)
            while ev < len(events) and (i + 1 == len(ns) or event_ns[ev] < ns[i + 1]):
                name = events[ev][1]
                if name == end_phase:
                    words.extend(stream.finish())
                    finished = True
                else:
                    words.extend(stream.mark_boundary(t, name))
                ev += 1
            if finished:
                break
        out[arm] = words
    return out


def trial_words(name: str, words: dict[str, list[Word]]) -> TrialWords:
    """TrialWords of per-arm word lists."""
    tw = TrialWords(name=name)
    for seq in words.values():
        for w in seq:
            tw.add(w)
    return tw


def offline_verdicts(
    model: SampleClassifier, trial: Trial, words: dict[str, list[Word]]
) -> list[str]:
    """The model's verdict on each sub-task of the trial from the given words (spec 2.7 split)."""

    samples = split_words(
        trial_words(trial.name, words),
        trial.state_times,
        trial.end_time,
        trial.phase_names,
        trial_tracks(trial),
    )
    if not samples:
        return []
    return [str(v) for v in model.predict_samples(samples)]


def first_word_mismatch(node: Sequence[Word], offline: Sequence[Word]) -> str:
    """'' when both sequences are identical (including seq), else a description of the first difference."""
    for i, (a, b) in enumerate(zip(node, offline, strict=False)):
        if a != b or a.seq != b.seq:
            return f"word {i}: node {a} != offline {b}"
    if len(node) != len(offline):
        return f"node has {len(node)} words, offline {len(offline)}"
    return ""


def truth_at(trial: Trial, t: np.ndarray) -> np.ndarray:
    """True sub-task name at each stream time (state times relative to the first sample)."""
    phases = trial.phase_names
    starts = np.asarray(trial.state_times[: len(phases)], dtype=float) - float(trial.time[0])
    idx = np.searchsorted(starts, t, side="right") - 1
    names = np.array(["unknown", *phases[: len(starts)]], dtype=object)
    return names[np.clip(idx + 1, 0, len(starts))]


def time_accuracy(
    trial: Trial,
    changes: Sequence[tuple[float, str]],
    initial: str = "unknown",
    step: float = 0.001,
) -> float:
    """Fraction of the trial's duration during which /task_state equals the true sub-task.

    `changes` are (stream time, state) in arrival order; the state holds until the next change.
    """
    duration = float(trial.time[-1] - trial.time[0])
    if duration <= 0:
        return 0.0
    grid = np.arange(0.0, duration, step)
    times = np.asarray([c[0] for c in changes], dtype=float)
    states = np.array([initial, *[c[1] for c in changes]], dtype=object)
    current = states[np.searchsorted(times, grid, side="right")]
    return float(np.mean(current == truth_at(trial, grid)))


def percentiles_ms(latencies_ns: Sequence[int]) -> dict[str, float | int | None]:
    """p50 / p99 / max (ms) and count of latencies in ns."""
    if not latencies_ns:
        return {"p50": None, "p99": None, "max": None, "n": 0}
    a = np.asarray(latencies_ns, dtype=float) / 1e6
    return {
        "p50": round(float(np.percentile(a, 50)), 3),
        "p99": round(float(np.percentile(a, 99)), 3),
        "max": round(float(a.max()), 3),
        "n": len(a),
    }

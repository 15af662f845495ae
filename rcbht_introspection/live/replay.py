"""Offline live-belief replay: what /task_state the nodes publish for a trial, without ROS.

`stream_trial` feeds a trial to `SegmenterSession` (the segmenter node's own state) sample by
sample, each /task_phase event applied right after the last sample before it, and logs every step
that released words or applied an event, with its stream time: the exact release time of each
word. `replay_beliefs` drives `BeliefTracker` (the classifier node's own state) with that log as
the classifier node does (words, then events, then final verdicts, then the current belief; a
/task_state change by the node's rule, live/state.py) and scores the timeline with
`offline.time_accuracy`, the state changes per sub-task and the reliability of the probabilities. Differences from a DDS replay: no transport delays (a belief changes at
the stream time of the sample that caused it) and one classification per step.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rcbht_introspection.io.bags import trial_phase_events
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.live import BeliefMode, offline
from rcbht_introspection.live.belief import UNKNOWN, Belief, BeliefTracker, SampleClassifier
from rcbht_introspection.live.reliability import expected_calibration_error, top_label
from rcbht_introspection.live.segmenter import PhaseEvent, SegmenterSession, WordBatch
from rcbht_introspection.live.state import StateFilter, TaskStateConfig
from rcbht_introspection.taxonomy.stream import ArmStream
from rcbht_introspection.taxonomy.words import TrialWords, Word

STAMP_ORIGIN_NS = 1_000_000_000
"""Absolute stamp of trial time 0 (a zero stamp is rejected by the segmenter, as in bags)."""


@dataclass(frozen=True)
class StreamStep:
    """What one sample (or the events after it) released, at stream time `t`."""

    t: float
    batches: tuple[WordBatch, ...]
    phases: tuple[PhaseEvent, ...]


@dataclass
class StreamedTrial:
    """The segmenter's output for one trial, step by step (only steps with output)."""

    name: str
    arms: tuple[str, ...]
    steps: list[StreamStep]
    duration: float

    def released(self) -> list[tuple[float, Word]]:
        """(release time, word) for every word, in release order."""
        return [(s.t, w) for s in self.steps for b in s.batches for w in b.words]

    def subtask_windows(self) -> list[tuple[str, float, float]]:
        """(sub-task, start, end) on the stream clock, as the classifier sees the events."""
        events = [p for s in self.steps for p in s.phases]
        out: list[tuple[str, float, float]] = []
        for i, p in enumerate(events):
            if p.end:
                continue
            end = events[i + 1].time if i + 1 < len(events) else self.duration
            out.append((p.name, p.time, end))
        return out


def stream_trial(
    trial: Trial, stream_factory: Callable[[str], ArmStream], end_phase: str = "done"
) -> StreamedTrial:
    """Feed `trial` to a SegmenterSession as segmenter_node is fed by its trial bag."""
    arms = trial.arms
    session = SegmenterSession(arms, stream_factory, end_phases=(end_phase,))
    ns = STAMP_ORIGIN_NS + np.rint(np.asarray(trial.time, dtype=float) * 1e9).astype(np.int64)
    events = trial_phase_events(trial, end_phase)
    event_ns = [STAMP_ORIGIN_NS + round(t * 1e9) for t, _ in events]
    steps: list[StreamStep] = []
    ev = 0
    for i in range(len(ns)):
        stamp = int(ns[i])
        batches: list[WordBatch] = []
        phases: list[PhaseEvent] = []
        for arm in arms:
            out = session.push(arm, stamp, trial.wrench[arm][i])
            batches.extend(out.batches)
        ended = False
        # events before the next sample apply at this one (the bag plays them right after it)
        while ev < len(events) and (i + 1 == len(ns) or event_ns[ev] < ns[i + 1]):
            out = session.phase(events[ev][1])
            batches.extend(out.batches)
            phases.extend(out.phases)
            ended = ended or any(p.end for p in out.phases)
            ev += 1
        if batches or phases:
            t = (stamp - int(ns[0])) / 1e9
            steps.append(StreamStep(t, tuple(batches), tuple(phases)))
        if ended:
            break
    duration = float(trial.time[-1] - trial.time[0]) if len(trial.time) else 0.0
    return StreamedTrial(trial.name, arms, steps, duration)


@dataclass
class LiveReplay:
    """The /task_state timeline and verdicts the classifier node produces for one trial."""

    name: str
    mode: BeliefMode
    changes: list[tuple[float, str]]
    finals: list[Belief]
    initial: str = UNKNOWN
    time_accuracy: float = float("nan")
    n_beliefs: int = 0
    extra: dict[str, object] = field(default_factory=dict)
    running: list[tuple[float, bool]] = field(default_factory=list)
    belief_changes: list[tuple[float, str]] = field(default_factory=list)
    """Every change of the running belief's sub-task ("unknown" included): /task_state without
    a state rule, for comparison."""
    belief_time_accuracy: float = float("nan")
    """(confidence, correct at that time) of each running belief with evidence (with a trial)."""
    final_times: list[float] = field(default_factory=list)
    """Stream time at which each of `finals` was issued (the step that made its words final)."""

    @property
    def verdicts(self) -> list[str]:
        return [b.subtask for b in self.finals]


def replay_beliefs(
    streamed: StreamedTrial,
    model: SampleClassifier | None,
    mode: BeliefMode = "boundary",
    window_s: float = 2.0,
    end_phase: str = "done",
    trial: Trial | None = None,
    state_config: TaskStateConfig | None = None,
) -> LiveReplay:
    """Drive BeliefTracker with the segmenter's steps as classifier_node does (/task_state by
    `state_config`, default TaskStateConfig()); score vs `trial`."""
    tracker = BeliefTracker(model, mode, window_s, end_phases=(end_phase,), trial=streamed.name)
    state = StateFilter(state_config)
    changes: list[tuple[float, str]] = []
    finals: list[Belief] = []
    final_times: list[float] = []
    running: list[tuple[float, Belief]] = []
    belief_changes: list[tuple[float, str]] = []
    n = 0
    for step in streamed.steps:
        for batch in step.batches:
            now = (batch.stamp_ns - batch.origin_ns) / 1e9
            tracker.add_words(batch.arm, batch.words, now)
            if batch.end_of_stream:
                tracker.end_of_stream(batch.arm)
        for p in step.phases:
            tracker.phase(p.name, p.time)
        issued = tracker.take_finals()
        finals.extend(issued)
        final_times.extend(step.t for _ in issued)
        belief = tracker.current()
        n += 1
        if belief.subtask != UNKNOWN and belief.probabilities:
            running.append((step.t, belief))
        if belief.subtask != (belief_changes[-1][1] if belief_changes else UNKNOWN):
            belief_changes.append((step.t, belief.subtask))
        if state.update(tracker.now, belief):
            changes.append((step.t, state.state))
    out = LiveReplay(streamed.name, mode, changes, finals, UNKNOWN, n_beliefs=n)
    out.belief_changes = belief_changes
    out.final_times = final_times
    if trial is not None:
        out.time_accuracy = offline.time_accuracy(trial, changes, initial=UNKNOWN)
        out.belief_time_accuracy = offline.time_accuracy(trial, belief_changes, initial=UNKNOWN)
        truth = offline.truth_at(trial, np.asarray([t for t, _ in running], dtype=float))
        for (_, b), true in zip(running, truth, strict=True):
            conf, hit = top_label([b.probabilities], b.classes, [str(true)])
            out.running.append((float(conf[0]), bool(hit[0])))
    return out


def commanded_phase(streamed: StreamedTrial, trial: Trial) -> tuple[float, int]:
    """(time_accuracy, state changes) of the baseline without words: /task_state = the name of
    each sub-task event as it is applied (what the task's state machine commanded)."""
    changes = [(start, name) for name, start, _ in streamed.subtask_windows()]
    return offline.time_accuracy(trial, changes, initial=UNKNOWN), len(changes)


def live_replay(
    trial: Trial,
    model: SampleClassifier | None,
    stream_factory: Callable[[str], ArmStream],
    mode: BeliefMode = "boundary",
    window_s: float = 2.0,
    state_config: TaskStateConfig | None = None,
) -> LiveReplay:
    """stream_trial + replay_beliefs for one trial."""
    streamed = stream_trial(trial, stream_factory)
    return replay_beliefs(streamed, model, mode, window_s, trial=trial, state_config=state_config)


def replay_summary(replays: Sequence[LiveReplay], trials: Sequence[Trial]) -> dict[str, Any]:
    """Duration-weighted time_accuracy, state changes per sub-task boundary (each sub-task start,
    the stream's first included), sub-task accuracy of final verdicts and the expected calibration
    error of final and running probabilities, over trials."""
    weights = [float(t.time[-1] - t.time[0]) for t in trials]
    acc = [r.time_accuracy for r in replays]
    correct = total = 0
    final_conf: list[float] = []
    final_hit: list[bool] = []
    for r, t in zip(replays, trials, strict=True):
        truth = [s for s, _, _ in t.subtask_bounds()]
        total += len(truth)
        correct += sum(v == s for v, s in zip(r.verdicts, truth, strict=False))
        for b, true in zip(r.finals, truth, strict=False):
            if b.probabilities:
                conf, hit = top_label([b.probabilities], b.classes, [true])
                final_conf.append(float(conf[0]))
                final_hit.append(bool(hit[0]))
    changes = sum(len(r.changes) for r in replays)
    belief_changes = sum(len(r.belief_changes) for r in replays)
    running = [c for r in replays for c in r.running]
    boundary = bool(replays) and replays[0].mode == "boundary"

    def weighted(values: Sequence[float]) -> float | None:
        return round(float(np.average(values, weights=weights)), 4) if replays else None

    return {
        "time_accuracy": weighted(acc),
        "subtask_accuracy": round(correct / total, 4) if total and boundary else None,
        "subtasks": total,
        "state_changes": changes,
        "state_changes_per_boundary": round(changes / total, 3) if total else None,
        "without_state_rule": {
            "time_accuracy": weighted([r.belief_time_accuracy for r in replays]),
            "state_changes": belief_changes,
            "state_changes_per_boundary": round(belief_changes / total, 3) if total else None,
        },
        "expected_calibration_error": {
            "final": _rounded(expected_calibration_error(final_conf, final_hit)),
            "running": _rounded(
                expected_calibration_error([c for c, _ in running], [h for _, h in running])
            ),
        },
        "per_trial": {r.name: round(r.time_accuracy, 4) for r in replays},
    }


def _rounded(value: float | None) -> float | None:
    return None if value is None else round(value, 4)


def words_until(released: Sequence[tuple[float, Word]], t: float, name: str = "") -> TrialWords:
    """TrialWords of the words released at or before stream time `t`."""
    out = TrialWords(name=name)
    for when, w in released:
        if when > t:
            break
        out.add(w)
    return out

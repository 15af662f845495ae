"""Offline live-belief replay: what /task_state the nodes publish for trials, without ROS.

`stream_trial` feeds a trial to `SegmenterSession` (the segmenter node's own state) sample by
sample, each /task_phase event applied right after the last sample before it, and logs every step
that released words or applied an event, with its stream time: the exact release time of each
word (what live-like training samples use, learn/live.py). `node_stream` feeds trials one after
another to one SegmenterSession exactly as segmenter_node is fed by their bags played in turn
(each message with its publication order as source timestamp, so an event waits for the next
sample, and the end event for the flush), one step per segmenter output. `replay_beliefs` hands
what segmenter_node would publish for those steps (live/publication.py) to one
`ClassifierSession` (the classifier node's own state: words, events, final verdicts, belief,
/task_state by live/state.py), so the beliefs and /task_state changes are those the nodes
publish, and scores the timeline with `offline.time_accuracy`, the state changes per sub-task and
the reliability of the probabilities. The one difference from a DDS replay: no transport delays
(a belief changes at the stream time of the sample that caused it).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rcbht_introspection.io.bags import trial_phase_events
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.live import BeliefMode, offline
from rcbht_introspection.live.belief import UNKNOWN, Belief, BeliefTracker, SampleClassifier
from rcbht_introspection.live.classifier import ClassifierSession, PhaseInput, WordsInput
from rcbht_introspection.live.join import Watermarks
from rcbht_introspection.live.publication import classifier_inputs, publication
from rcbht_introspection.live.reliability import expected_calibration_error, top_label
from rcbht_introspection.live.segmenter import Output, PhaseEvent, SegmenterSession, WordBatch
from rcbht_introspection.live.state import StateFilter, TaskStateConfig
from rcbht_introspection.summaries.blocks import WrenchTrack
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

    def wrench_tracks(self) -> dict[str, WrenchTrack]:
        """Each arm's wrench blocks as the segmenter sent them with its words."""
        tracks = {arm: WrenchTrack() for arm in self.arms}
        for step in self.steps:
            for batch in step.batches:
                tracks[batch.arm].extend(batch.wrench)
        return tracks

    def delivered_blocks(self) -> Callable[[int], dict[str, WrenchTrack]]:
        """`step index -> each arm's blocks sent with the batches up to that step` (what the
        classifier has then: blocks ride on word batches, so they may lag the stream a little)."""
        tracks = self.wrench_tracks()
        last: list[dict[str, float]] = []
        known = dict.fromkeys(self.arms, -np.inf)
        for step in self.steps:
            for batch in step.batches:
                if batch.wrench:
                    known[batch.arm] = max(known[batch.arm], batch.wrench[-1].end)
            last.append(dict(known))

        def at(i: int) -> dict[str, WrenchTrack]:
            ends = last[i] if 0 <= i < len(last) else dict.fromkeys(self.arms, -np.inf)
            return {arm: track.until(ends[arm]) for arm, track in tracks.items()}

        return at

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


def node_stream(
    trials: Sequence[Trial], stream_factory: Callable[[str], ArmStream], end_phase: str = "done"
) -> list[StreamedTrial]:
    """The trials' streams as segmenter_node makes them from their bags played in turn, one
    step per output of the session."""
    if not trials:
        return []
    arms = trials[0].arms
    session = SegmenterSession(arms, stream_factory, end_phases=(end_phase,))
    source = itertools.count(1)  # publication order: the DDS source timestamps of the player
    out = []
    for trial in trials:
        if trial.arms != arms:
            raise ValueError(f"{trial.name}: arms {trial.arms} are not the first trial's {arms}")
        steps = [
            StreamStep(t, tuple(o.batches), tuple(o.phases))
            for t, o in _node_outputs(session, trial, end_phase, source)
            if o.batches or o.phases
        ]
        duration = float(trial.time[-1] - trial.time[0]) if len(trial.time) else 0.0
        out.append(StreamedTrial(trial.name, arms, steps, duration))
    return out


def _node_outputs(
    session: SegmenterSession[ArmStream], trial: Trial, end_phase: str, source: Iterator[int]
) -> Iterator[tuple[float, Output]]:
    """(stream time, output) of each call, in a trial bag's order (io/bags.write_trial_bag:
    each arm's sample, then the events before the next sample), each message with its source
    timestamp; the end event waits for the flush that follows the last sample."""
    ns = STAMP_ORIGIN_NS + np.rint(np.asarray(trial.time, dtype=float) * 1e9).astype(np.int64)
    events = trial_phase_events(trial, end_phase)
    event_ns = [STAMP_ORIGIN_NS + round(t * 1e9) for t, _ in events]
    ev = 0
    t = 0.0
    for i in range(len(ns)):
        t = (int(ns[i]) - int(ns[0])) / 1e9
        for arm in trial.arms:
            yield t, session.push(arm, int(ns[i]), trial.wrench[arm][i], next(source))
        while ev < len(events) and (i + 1 == len(ns) or event_ns[ev] < ns[i + 1]):
            yield t, session.phase(events[ev][1], next(source))
            ev += 1
    yield t, session.flush(next(source) + session.max_hold_ns)


def node_inputs(streamed: StreamedTrial) -> list[WordsInput | PhaseInput]:
    """What classifier_node receives of a `node_stream` trial, in publication order."""
    marks = Watermarks()  # numbering restarts with each stream: one per trial gives the node's
    return [
        item
        for s in streamed.steps
        for item in classifier_inputs(publication(Output(list(s.batches), list(s.phases)), marks))
    ]


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
    """(confidence, correct at that time) of each running belief with evidence (with a trial)."""
    belief_changes: list[tuple[float, str]] = field(default_factory=list)
    """Every change of the running belief's sub-task ("unknown" included): /task_state without
    a state rule, for comparison."""
    belief_time_accuracy: float = float("nan")
    final_times: list[float] = field(default_factory=list)
    """Stream time at which each of `finals` was issued (the sample whose input made its words
    final)."""
    beliefs: list[Belief] = field(default_factory=list)
    """Every belief the node publishes for the trial, in order (verdicts and running beliefs)."""

    @property
    def verdicts(self) -> list[str]:
        return [b.subtask for b in self.finals]


def replay_beliefs(
    streamed: Sequence[StreamedTrial],
    model: SampleClassifier | None,
    mode: BeliefMode = "boundary",
    window_s: float = 2.0,
    end_phase: str = "done",
    trials: Sequence[Trial] | None = None,
    state_config: TaskStateConfig | None = None,
    initial_state: str = UNKNOWN,
) -> list[LiveReplay]:
    """One classifier session fed what segmenter_node publishes for the streamed trials in turn
    (`node_stream`: successive streams of one node), /task_state by `state_config` (default
    TaskStateConfig()) from `initial_state`; each scored vs its trial in `trials`."""
    tracker = BeliefTracker(model, mode, window_s, end_phases=(end_phase,))
    session = ClassifierSession(tracker, StateFilter(state_config))
    session.state.state = initial_state
    out = []
    for k, one in enumerate(streamed):
        trial = trials[k] if trials is not None else None
        initial = session.state.state
        inputs = node_inputs(one)
        if inputs and inputs[0].stream == session.stream:
            raise ValueError(f"{one.name} continues the previous stream: stream with node_stream")
        step = session.receive(inputs)
        running = [b for b, _ in step.beliefs if not b.final]
        finals = [(b, trigger) for b, trigger in step.beliefs if b.final]
        origin = inputs[0].stream[0] if inputs else 0
        rep = LiveReplay(
            one.name,
            mode,
            [(t, s) for t, s in step.states],
            [b for b, _ in finals],
            initial,
            n_beliefs=len(running),
            final_times=[(trigger - origin) / 1e9 for _, trigger in finals],
            beliefs=[b for b, _ in step.beliefs],
        )
        for b in running:
            if b.subtask != (rep.belief_changes[-1][1] if rep.belief_changes else UNKNOWN):
                rep.belief_changes.append((b.end, b.subtask))
        if trial is not None:
            rep.time_accuracy = offline.time_accuracy(trial, rep.changes, initial=initial)
            rep.belief_time_accuracy = offline.time_accuracy(
                trial, rep.belief_changes, initial=UNKNOWN
            )
            scored = [b for b in running if b.subtask != UNKNOWN and b.probabilities]
            truth = offline.truth_at(trial, np.asarray([b.end for b in scored], dtype=float))
            for b, true in zip(scored, truth, strict=True):
                conf, hit = top_label([b.probabilities], b.classes, [str(true)])
                rep.running.append((float(conf[0]), bool(hit[0])))
        out.append(rep)
    return out


def commanded_phase(streamed: StreamedTrial, trial: Trial) -> tuple[float, int]:
    """(time_accuracy, state changes) of the baseline without words: /task_state = the name of
    each sub-task event as it is applied (what the task's state machine commanded)."""
    changes = [(start, name) for name, start, _ in streamed.subtask_windows()]
    return offline.time_accuracy(trial, changes, initial=UNKNOWN), len(changes)


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

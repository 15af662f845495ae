"""Scores of a replay through the nodes, from what was published and what came back (no ROS).

The observer (observer.py) fills `Observations`; after each bag the harness cuts that bag's
`BagRecord` out of them (`bag_record`), and `score` compares the records with the truth in the
trials and with the offline run of the same stream and model (rcbht_introspection.live.offline).
Its dict is the JSON that `rcbht replay-eval` prints and writes.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from rcbht_introspection.configure.params import LEVEL_TOPICS
from rcbht_introspection.io.bags import END_PHASE, WRENCH_TYPE, BagMessage, decode_wrench
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.live import BeliefMode, offline
from rcbht_introspection.live.belief import UNKNOWN, Belief
from rcbht_introspection.live.reliability import expected_calibration_error, top_label
from rcbht_introspection.live.replay import LiveReplay, node_stream, replay_beliefs
from rcbht_introspection.live.state import TaskStateConfig
from rcbht_introspection.taxonomy.stream import ArmStream
from rcbht_introspection.taxonomy.words import LEVELS, Word

if TYPE_CHECKING:
    from rcbht_introspection.learn.models import SubtaskModel


@dataclass(frozen=True)
class ReceivedBelief:
    """A Belief message as the observer received it."""

    wall_ns: int
    """Wall clock here when it arrived."""
    belief: Belief
    trigger_ns: int
    """Stamp of the wrench sample whose words caused it."""
    sent_ns: int
    """Wall clock of the classifier when it published it."""


@dataclass(frozen=True)
class AppliedPhase:
    """A sub-task or end event as the segmenter applied it."""

    wall_ns: int
    name: str
    time: float
    """Stream time of the event."""
    stream_id: int
    stamp_ns: int
    """Stamp of the wrench sample it was applied at."""


@dataclass(frozen=True)
class Mark:
    """How far the observations had got when a bag started: what came later is that bag's."""

    word_arrivals: int
    beliefs: int
    states: int
    initial_state: str
    """/task_state when the bag started."""


@dataclass
class Observations:
    """What the observer received, with wall-clock receive times (ns); lists only grow."""

    states: list[tuple[int, str]] = field(default_factory=list)
    """(wall ns, /task_state) of each change"""
    beliefs: list[ReceivedBelief] = field(default_factory=list)
    words: dict[tuple[int, str, str], list[Word]] = field(default_factory=dict)
    """(stream id, arm, level topic) -> words in arrival order"""
    ends: dict[tuple[int, str, str], tuple[int, int]] = field(default_factory=dict)
    """(stream id, arm, level topic) -> (samples accepted, rejected) at end of stream"""
    triggers: dict[int, set[int]] = field(default_factory=dict)
    """stream id -> stamps of wrench samples that finalised words"""
    word_arrivals: list[tuple[int, int]] = field(default_factory=list)
    """(wall ns, stamp of the sample that finalised them) of each non-empty Words message"""
    phases: list[AppliedPhase] = field(default_factory=list)

    def mark(self) -> Mark:
        """Where the observations stand now (see Mark)."""
        return Mark(
            len(self.word_arrivals),
            len(self.beliefs),
            len(self.states),
            self.states[-1][1] if self.states else "unknown",
        )

    def ended(self, stream_id: int, arms: Sequence[str]) -> bool:
        """Every word topic of every arm has ended stream `stream_id`."""
        return all((stream_id, arm, level) in self.ends for arm in arms for level in LEVEL_TOPICS)

    def finals_since(self, index: int) -> list[ReceivedBelief]:
        """The final beliefs (sub-task verdicts) from belief `index` on."""
        return [b for b in self.beliefs[index:] if b.belief.final]


@dataclass
class Playback:
    """What the harness published of one bag: wrench stamps and when they went out."""

    bag: Path
    origin: int | None = None
    """Stamp (ns) of the first wrench sample."""
    published: int = 0
    """Wrench messages published (every arm)."""
    play_s: float = 0.0
    pub_wall: dict[int, int] = field(default_factory=dict)
    """wrench stamp -> wall ns it was first published"""
    pub_series: list[tuple[int, int]] = field(default_factory=list)
    """(wall ns, stamp) of each new stamp, in publishing order"""

    def on_publish(self, message: BagMessage, wall_ns: int) -> None:
        """Count one published bag message (the player's callback)."""
        if message.msgtype != WRENCH_TYPE:
            return
        stamp = decode_wrench(message.raw)[0]
        if self.origin is None:
            self.origin = stamp
        self.published += 1
        if stamp not in self.pub_wall:
            self.pub_wall[stamp] = wall_ns
            self.pub_series.append((wall_ns, stamp))


@dataclass(frozen=True)
class BagRecord:
    """One bag's raw record: what was published and what came back for its stream."""

    playback: Playback
    initial_state: str
    beliefs: list[ReceivedBelief]
    word_arrivals: list[tuple[int, int]]
    states: list[tuple[int, str]]
    words: dict[tuple[str, str], list[Word]]
    """(arm, level topic) -> words"""
    ends: dict[tuple[str, str], tuple[int, int]]
    """(arm, level topic) -> cumulative (samples accepted, rejected) at its end of stream"""
    triggers: set[int]
    event_stamps: set[int]
    """Stamps of the samples at which events were applied (their words are the event's)."""


def bag_record(
    obs: Observations, since: Mark, stream_id: int, arms: Sequence[str], playback: Playback
) -> BagRecord:
    """The record of stream `stream_id`, observed from `since` on."""
    return BagRecord(
        playback=playback,
        initial_state=since.initial_state,
        beliefs=list(obs.beliefs[since.beliefs :]),
        word_arrivals=list(obs.word_arrivals[since.word_arrivals :]),
        states=list(obs.states[since.states :]),
        words={
            (arm, level): list(obs.words.get((stream_id, arm, level), []))
            for arm in arms
            for level in LEVEL_TOPICS
        },
        ends={k[1:]: v for k, v in obs.ends.items() if k[0] == stream_id},
        triggers=set(obs.triggers.get(stream_id, set())),
        event_stamps={p.stamp_ns for p in obs.phases if p.stream_id == stream_id},
    )


@dataclass(frozen=True)
class Reference:
    """The offline run to compare with: the model, the arm streams of the nodes' profiles and
    the classifier's settings."""

    model: SubtaskModel
    stream_factory: Callable[[str], ArmStream]
    state: TaskStateConfig | None = None
    """classifier_node's `state.*` (None: TaskStateConfig())."""
    window_s: float = 2.0


@dataclass
class Latencies:
    """Latencies (ns) from a wrench sample's publication, over all bags."""

    belief: list[int] = field(default_factory=list)
    """-> the classifier published a belief the words that sample finalised caused"""
    received: list[int] = field(default_factory=list)
    """-> that belief arrived here"""
    word: list[int] = field(default_factory=list)
    """-> the words it finalised arrived here"""
    event: list[int] = field(default_factory=list)
    """-> a belief of words finalised by an event applied at that sample"""

    def add(self, rec: BagRecord) -> None:
        """Add one bag's latencies (final beliefs and unpublished triggers have none)."""
        # words finalised by a sub-task or end event are the event's, not a sample's: the end
        # event waits for sample silence, so they are reported apart
        pub_wall = rec.playback.pub_wall
        for r in rec.beliefs:
            trig = r.trigger_ns
            if trig in rec.triggers and trig in pub_wall and not r.belief.final:
                if trig in rec.event_stamps:
                    self.event.append(r.sent_ns - pub_wall[trig])
                    continue
                self.belief.append(r.sent_ns - pub_wall[trig])
                self.received.append(r.wall_ns - pub_wall[trig])
        for wall, trig in rec.word_arrivals:
            if trig in pub_wall and trig not in rec.event_stamps:
                self.word.append(wall - pub_wall[trig])


def state_timeline(rec: BagRecord) -> list[tuple[float, str]]:
    """/task_state changes on the stream clock (wall receive time -> data time).

    Empty when no wrench was published: nothing places the changes on the stream clock.
    """
    series = rec.playback.pub_series
    if not series or rec.playback.origin is None:
        return []
    walls = np.asarray([w for w, _ in series], dtype=float)
    data_t = (np.asarray([s for _, s in series], dtype=float) - rec.playback.origin) / 1e9
    return [(float(np.interp(w, walls, data_t)), s) for w, s in rec.states]


def _offline_comparison(
    rec: BagRecord, trial: Trial, verdicts: list[str], arms: Sequence[str], ref: Reference
) -> dict[str, Any]:
    """The node's words and verdicts of one bag against the offline run of the same trial."""
    off_words = offline.offline_stream_words(trial, ref.stream_factory, END_PHASE)
    mismatch = ""
    for arm in arms:
        for level in LEVELS:
            node_seq = rec.words[(arm, level.value + "s")]
            off_seq = [w for w in off_words[arm] if w.level == level]
            why = offline.first_word_mismatch(node_seq, off_seq)
            if why and not mismatch:
                mismatch = f"arm {arm} {level.value}: {why}"
    node_words = {
        arm: [w for lv in LEVELS for w in rec.words[(arm, lv.value + "s")]] for arm in arms
    }
    off_verdicts = offline.offline_verdicts(ref.model, trial, off_words)
    return {
        "offline_words": sum(len(v) for v in off_words.values()),
        "words_match_offline": not mismatch,
        "words_mismatch": mismatch,
        "offline_verdicts": off_verdicts,
        "offline_verdicts_of_node_words": offline.offline_verdicts(ref.model, trial, node_words),
        "verdicts_match_offline": verdicts == off_verdicts,
    }


def _offline_states(
    records: Sequence[BagRecord], trials: Sequence[Trial], mode: BeliefMode, ref: Reference
) -> list[LiveReplay]:
    """The nodes' sessions run offline on the bags in turn, from the first bag's /task_state."""
    return replay_beliefs(
        node_stream(trials, ref.stream_factory, END_PHASE),
        ref.model,
        mode,
        ref.window_s,
        END_PHASE,
        trials,
        ref.state,
        records[0].initial_state if records else UNKNOWN,
    )


def _belief_key(b: Belief) -> tuple[object, ...]:
    return (b.subtask, b.probabilities, b.start, b.end, b.phase, b.final, b.n_words, b.blind)


@dataclass
class _Tally:
    """Running totals of a scoring pass over the bags."""

    correct: int = 0
    total: int = 0
    verdicts_match: bool = True
    words_match: bool = True
    dropped: int = 0
    rejected: int = 0
    state_changes: int = 0
    latencies: Latencies = field(default_factory=Latencies)
    time_acc: list[tuple[float, float]] = field(default_factory=list)
    """(time accuracy, duration) of each bag"""
    final_conf: list[float] = field(default_factory=list)
    final_hit: list[bool] = field(default_factory=list)
    running_conf: list[float] = field(default_factory=list)
    running_hit: list[bool] = field(default_factory=list)

    def accepted(
        self, rec: BagRecord, arms: Sequence[str], prev_accepted: dict[str, int]
    ) -> dict[str, int]:
        """Samples the segmenter accepted for this bag per arm (its counters are cumulative:
        `prev_accepted` holds and is moved to the counts after the previous bag)."""
        accepted = {}
        for arm in arms:
            acc, rej = rec.ends.get((arm, "primitives"), (prev_accepted[arm], 0))
            accepted[arm] = acc - prev_accepted[arm]
            prev_accepted[arm] = acc
            self.rejected = max(self.rejected, rej)
        return accepted

    def calibration(
        self, rec: BagRecord, trial: Trial, finals: list[Belief], truth: list[str]
    ) -> None:
        """The top label's confidence and hit of each final belief and each running one."""
        for b, true in zip(finals, truth, strict=False):
            if b.probabilities:
                conf, hit = top_label([b.probabilities], b.classes, [true])
                self.final_conf.append(float(conf[0]))
                self.final_hit.append(bool(hit[0]))
        running = [
            r.belief
            for r in rec.beliefs
            if not r.belief.final and r.belief.probabilities and r.belief.subtask != UNKNOWN
        ]
        at = offline.truth_at(trial, np.asarray([b.end for b in running], dtype=float))
        for b, true in zip(running, at, strict=True):
            conf, hit = top_label([b.probabilities], b.classes, [str(true)])
            self.running_conf.append(float(conf[0]))
            self.running_hit.append(bool(hit[0]))


def _bag_scores(
    tally: _Tally, rec: BagRecord, trial: Trial, arms: Sequence[str], prev_accepted: dict[str, int]
) -> dict[str, Any]:
    """One bag's record against its truth (verdicts, time accuracy, drops), added to `tally`."""
    truth = [s for s, _, _ in trial.subtask_bounds()]
    finals = [r.belief for r in rec.beliefs if r.belief.final]
    verdicts = [b.subtask for b in finals]
    tally.total += len(truth)
    tally.correct += sum(1 for v, t in zip(verdicts, truth, strict=False) if v == t)
    bag_dropped = rec.playback.published - sum(tally.accepted(rec, arms, prev_accepted).values())
    tally.dropped += bag_dropped
    tally.latencies.add(rec)
    tally.calibration(rec, trial, finals, truth)
    changes = state_timeline(rec)
    acc_t = offline.time_accuracy(trial, changes, initial=rec.initial_state)
    tally.state_changes += len(changes)
    duration = float(trial.time[-1] - trial.time[0])
    tally.time_acc.append((acc_t, duration))
    return {
        "name": trial.name,
        "truth": truth,
        "truth_starts": [round(s - float(trial.time[0]), 6) for _, s, _ in trial.subtask_bounds()],
        "duration": round(duration, 6),
        "verdicts": verdicts,
        "final_probabilities": [dict(zip(b.classes, b.probabilities, strict=True)) for b in finals],
        "time_accuracy": round(acc_t, 4),
        "timeline": [(round(t, 3), s) for t, s in changes],
        "initial_state": rec.initial_state,
        "published_wrench": rec.playback.published,
        "dropped_wrench": bag_dropped,
        "play_s": round(rec.playback.play_s, 2),
        "node_words": sum(len(v) for v in rec.words.values()),
    }


def _offline_bag(
    tally: _Tally,
    bag_out: dict[str, Any],
    rec: BagRecord,
    trial: Trial,
    arms: Sequence[str],
    mode: BeliefMode,
    reference: Reference,
    run: LiveReplay,
) -> None:
    """Add one bag's comparison with the offline run (words, verdicts, states, beliefs)."""
    bag_out.update(_offline_comparison(rec, trial, bag_out["verdicts"], arms, reference))
    tally.words_match &= bag_out["words_match_offline"]
    if mode == "boundary":
        tally.verdicts_match &= bag_out["verdicts_match_offline"]
    bag_out.update(
        {
            "offline_timeline": [(round(t, 3), s) for t, s in run.changes],
            "offline_time_accuracy": round(run.time_accuracy, 4),
            "states_match_offline": [s for _, s in rec.states] == [s for _, s in run.changes],
            "beliefs_match_offline": [_belief_key(r.belief) for r in rec.beliefs]
            == [_belief_key(b) for b in run.beliefs],
        }
    )


def _offline_summary(
    bags_out: list[dict[str, Any]], runs: list[LiveReplay], tally: _Tally, weight: float
) -> dict[str, Any]:
    """Whether every bag's states and beliefs matched the offline run, and its accuracy."""
    return {
        "states_match_offline": all(b["states_match_offline"] for b in bags_out),
        "beliefs_match_offline": all(b["beliefs_match_offline"] for b in bags_out),
        "offline_time_accuracy": round(
            sum(r.time_accuracy * d for r, (_, d) in zip(runs, tally.time_acc, strict=True))
            / weight,
            4,
        ),
        "offline_state_changes": sum(len(r.changes) for r in runs),
    }


def score(
    records: Sequence[BagRecord],
    trials: Sequence[Trial],
    arms: Sequence[str],
    mode: BeliefMode,
    reference: Reference | None = None,
    accepted_before: Mapping[str, int] | None = None,
) -> dict[str, Any]:
    """Scores over all bags plus a per-bag record (without a reference: no offline figures).

    `accepted_before`: per arm, the samples the segmenter accepted for bags played before these
    (its counters are cumulative), e.g. the bags a teaching replay taught."""
    tally = _Tally()
    bags_out = []
    prev_accepted = {arm: (accepted_before or {}).get(arm, 0) for arm in arms}
    offline_runs = _offline_states(records, trials, mode, reference) if reference else []
    for k, (rec, trial) in enumerate(zip(records, trials, strict=True)):
        bag_out = _bag_scores(tally, rec, trial, arms, prev_accepted)
        if reference is not None:
            _offline_bag(tally, bag_out, rec, trial, arms, mode, reference, offline_runs[k])
        bags_out.append(bag_out)
    weight = sum(d for _, d in tally.time_acc) or 1.0
    boundary = mode == "boundary"
    offline_states: dict[str, Any] = {}
    if reference is not None:
        offline_states = _offline_summary(bags_out, offline_runs, tally, weight)
    total, correct, lat = tally.total, tally.correct, tally.latencies
    return {
        "subtask_accuracy": round(correct / total, 4) if total and boundary else None,
        "subtasks": total,
        "subtasks_correct": correct,
        "verdicts_match_offline": (
            tally.verdicts_match if reference is not None and boundary else None
        ),
        "time_accuracy": round(sum(a * d for a, d in tally.time_acc) / weight, 4),
        "state_changes": tally.state_changes,
        "state_changes_per_boundary": round(tally.state_changes / total, 3) if total else None,
        "expected_calibration_error": {
            "final": _rounded(expected_calibration_error(tally.final_conf, tally.final_hit)),
            "running": _rounded(expected_calibration_error(tally.running_conf, tally.running_hit)),
        },
        "dropped_wrench": tally.dropped,
        "rejected_wrench": tally.rejected,
        "words_match_offline": tally.words_match if reference is not None else None,
        **offline_states,
        "latency_ms": offline.percentiles_ms(lat.belief),
        "latency_received_ms": offline.percentiles_ms(lat.received),
        "word_latency_ms": offline.percentiles_ms(lat.word),
        "event_latency_ms": offline.percentiles_ms(lat.event),
        "per_bag": bags_out,
    }


def _rounded(value: float | None) -> float | None:
    return None if value is None else round(value, 4)


def summary(result: dict[str, Any], timeline: bool = False) -> str:
    """Human-readable report of a replay-eval result."""
    lines = []
    for b in result["per_bag"]:
        lines.append(f"{b['name']}: truth {b['truth']}")
        lines.append(f"  verdicts {b['verdicts']}  (offline {b.get('offline_verdicts')})")
        if timeline:
            truth = ", ".join(
                f"{t:.2f}s {s}" for t, s in zip(b["truth_starts"], b["truth"], strict=True)
            )
            lines.append(f"  truth:       {truth}, end {b['duration']:.2f}s")
            steps = ", ".join(f"{t:.2f}s {s}" for t, s in b["timeline"])
            lines.append(f"  /task_state: start {b['initial_state']}, {steps}")
    lat = result["latency_ms"]
    teach = result.get("teach")
    if teach:
        lines.append(
            f"taught {len(teach['taught_trials'])} trials ({teach['taught_windows']} windows, "
            f"model version {teach['model_version']}, errors {teach['errors']}); learned in "
            f"{teach['trial_latency_s']} s per trial"
        )
        if "latency_beside_ms" in teach:
            beside = teach["latency_beside_ms"]
            lines.append(
                f"sample -> belief while learning beside: p50 {beside['p50']} ms, "
                f"p99 {beside['p99']} ms, max {beside['max']} ms (n {beside['n']})"
            )
    if "restart" in result:
        lines.append(
            f"after a restart from the saved model: verdicts equal {result['restart']['verdicts_equal']}"
        )
    lines.append(
        f"subtask_accuracy {result['subtask_accuracy']} ({result['subtasks_correct']}/{result['subtasks']}), "
        f"time_accuracy {result['time_accuracy']}, state changes {result['state_changes']} "
        f"({result['state_changes_per_boundary']} per sub-task boundary), "
        f"ECE final {result['expected_calibration_error']['final']} "
        f"running {result['expected_calibration_error']['running']}, verdicts_match_offline {result['verdicts_match_offline']}, "
        f"words_match_offline {result['words_match_offline']}, "
        f"states_match_offline {result.get('states_match_offline')} (offline time_accuracy "
        f"{result.get('offline_time_accuracy')}, {result.get('offline_state_changes')} changes), "
        f"dropped_wrench {result['dropped_wrench']}, "
        f"latency p50 {lat['p50']} ms p99 {lat['p99']} ms (n={lat['n']}), "
        f"clean_shutdown {result['clean_shutdown']}, rate {result['rate']}x, {result['wall_s']} s"
    )
    return "\n".join(lines)

"""verifier_node's state without ROS: wrench samples and /task_phase events in, verdicts out.

The samples and events go through a SegmenterSession, so the verifier checks samples, places
events on the stream clock and starts streams exactly as segmenter_node does (stream time from
the stream's first accepted sample; an end event ends the stream and the next sample starts a
new one, with a new VerifierSession). No tare or gravity compensation: the verifier model is
trained on the wrench as recorded.

An event applies at the last sample before it (segmenter_node's Phase.time), and that sample
counts as the new sub-task's first one: each arm's latest sample is held back until the arm's
next sample or event, so the verdicts equal those of `offline_verdicts` - the trial's samples and
events fed as the offline verifier features feed them (verify/features.trial_features) - at
the cost of one sample period of latency.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

from rcbht_introspection.io.bags import END_PHASE, trial_phase_events
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.live.belief import Belief
from rcbht_introspection.live.health import ERROR, OK, WARN, CounterWatch, Health, LatencyWindow
from rcbht_introspection.live.segmenter import SegmenterSession
from rcbht_introspection.taxonomy.words import Word
from rcbht_introspection.verify.mismatch import Contradiction, contradiction_of
from rcbht_introspection.verify.model_file import VerifierModel
from rcbht_introspection.verify.monitor import Verdict, VerifierSession

NO_MODEL = "unknown"
"""Health without a usable verifier model: nothing is judged, nothing is claimed."""


@dataclass(frozen=True)
class StreamVerdict:
    """A verdict with the stream it belongs to and the evidence window it rests on."""

    verdict: Verdict
    stream_id: int
    origin_ns: int
    evidence_start: float
    """Onset estimate once the alarm fired, else the start of the running sub-task (0 before)."""

    @property
    def stamp_ns(self) -> int:
        """The tick on the wrench stamps' clock."""
        return self.origin_ns + round(self.verdict.time * 1e9)


@dataclass
class VerifierOutput:
    """What one call produced: verdicts in tick order, a rejection reason, an unknown event."""

    verdicts: list[StreamVerdict] = field(default_factory=list)
    rejected: str | None = None
    unknown_phase: str | None = None

    def alarm_line(self) -> str:
        """The log line of an alarm raised by these verdicts ('' when none was)."""
        for sv in self.verdicts:
            v = sv.verdict
            if v.alarm_time == v.time:
                return (
                    f"alarm at stream time {v.time:.3f} s in sub-task {v.phase!r}: {v.health} "
                    f"(score {v.score:.2f}, onset {v.onset})"
                )
        return ""


class _Stream:
    """One stream's VerifierSession, shared by its arms' feeds."""

    def __init__(self, model: VerifierModel, owner: VerifierStream) -> None:
        self.session = VerifierSession(model)
        self.owner = owner
        self.boundaries = 0
        """Sub-task events applied to the session (each arm marks every event once)."""
        self.feeds: set[str] = set()
        self.finished: set[str] = set()

    def collect(self, verdicts: list[Verdict]) -> None:
        owner = self.owner
        starts = [t for _, t in self.session.phases]
        for v in verdicts:
            if v.alarm and v.onset is not None:
                evidence = v.onset
            else:
                i = int(np.searchsorted(starts, v.time, side="right")) - 1
                evidence = starts[i] if i >= 0 else 0.0
            owner.pending.append(
                StreamVerdict(
                    v, owner.segmenter.stream_id, owner.segmenter.origin_ns or 0, evidence
                )
            )


class _ArmFeed:
    """One arm's feed into the stream's session (the ArmFeed the SegmenterSession drives)."""

    def __init__(self, stream: _Stream, arm: str) -> None:
        self.stream = stream
        self.arm = arm
        self.held: tuple[float, Sequence[float]] | None = None
        self.marked = 0

    def _release(self) -> None:
        if self.held is not None:
            t, values = self.held
            self.held = None
            self.stream.collect(self.stream.session.push(self.arm, t, values))

    def push(self, t: float, wrench6: Sequence[float]) -> list[Word]:
        self._release()
        self.held = (t, wrench6)
        return []

    def mark_boundary(self, t: float, subtask: str = "") -> list[Word]:
        self.marked += 1
        if self.marked > self.stream.boundaries:  # the first arm to reach this event applies it
            self.stream.boundaries += 1
            self.stream.session.phase(subtask, t)
        return []

    def finish(self) -> list[Word]:
        self._release()
        self.stream.finished.add(self.arm)
        if self.stream.finished >= set(self.stream.session.arms):
            self.stream.collect(self.stream.session.end())
        return []


class VerifierStream:
    """Samples and events of the verifier's arms -> verdicts, stream after stream."""

    def __init__(
        self,
        model: VerifierModel,
        arms: Sequence[str],
        end_phases: Sequence[str] = (END_PHASE,),
        subtasks: Sequence[str] | None = None,
        hold_s: float = 0.2,
        max_hold_s: float = 10.0,
    ) -> None:
        if set(arms) != set(model.arms):
            raise ValueError(
                f"arms {list(arms)} differ from the verifier model's {list(model.arms)}"
            )
        self.model = model
        self.pending: list[StreamVerdict] = []
        self._stream: _Stream | None = None
        self.segmenter: SegmenterSession[_ArmFeed] = SegmenterSession(
            arms, self._feed, end_phases, subtasks, hold_s, max_hold_s, summaries=False
        )
        self.health = NO_MODEL
        """The latest verdict's health (kept after a stream ends, until the next one's first);
        `unknown` before the first verdict: nothing has been judged yet."""
        self.verdicts = 0
        self.alarms = 0

    def statistics(self) -> str:
        """What the stream took in and said: a node's last line."""
        counts = {a: (c.accepted, c.rejected_total) for a, c in self.segmenter.counts.items()}
        return (
            f"verdicts published {self.verdicts}, alarms {self.alarms}, "
            f"samples (accepted, rejected) per arm {counts}"
        )

    def _feed(self, arm: str) -> _ArmFeed:
        """The SegmenterSession's stream factory: a new session when a new stream starts."""
        if self._stream is None or arm in self._stream.feeds:
            self._stream = _Stream(self.model, self)
        self._stream.feeds.add(arm)
        return _ArmFeed(self._stream, arm)

    def _take(self, rejected: str | None = None, unknown: str | None = None) -> VerifierOutput:
        out = VerifierOutput(self.pending, rejected, unknown)
        self.pending = []
        for sv in out.verdicts:
            self.verdicts += 1
            v = sv.verdict
            if v.alarm and v.alarm_time == v.time:
                self.alarms += 1
            self.health = v.health
        return out

    def push(
        self, arm: str, stamp_ns: int, wrench: Sequence[float], source_ns: int | None = None
    ) -> VerifierOutput:
        """One wrench sample (stamp on the sensor's clock, DDS source timestamp if known)."""
        out = self.segmenter.push(arm, stamp_ns, wrench, source_ns)
        return self._take(out.rejected)

    def phase(self, name: str, source_ns: int | None = None) -> VerifierOutput:
        """One /task_phase event."""
        out = self.segmenter.phase(name, source_ns)
        return self._take(unknown=out.unknown_phase)

    def belief(self, belief: Belief) -> Contradiction | None:
        """A belief of the classifier (rcbht/belief): a final verdict contradicting its
        commanded sub-task, on a sub-task of the running stream, feeds its mismatch signal from
        the stream's latest sample on (what the next verdicts judge). Returns the contradiction,
        if any."""
        stream = self._stream
        times = (self.segmenter.state[a].last_t for a in self.segmenter.arms)
        latest = [t for t in times if t is not None]
        if stream is None or stream.session.ended or not latest:
            return None
        known_at = max(latest)
        # a verdict of this stream: one of its sub-tasks, over before now (a late verdict on
        # the previous stream's last sub-task must not judge the next stream)
        ours = any(
            n == belief.phase and abs(t - belief.start) < 1e-6 for n, t in stream.session.phases
        )
        if not ours or belief.end > known_at + 1e-6:
            return None
        c = contradiction_of(belief, known_at, self.model.config.mismatch_min_probability)
        if c is not None:
            stream.session.contradict(c)
        return c

    def flush(self, now_ns: int) -> VerifierOutput:
        """Apply events that no later sample will apply (segmenter_node's flush rule)."""
        self.segmenter.flush(now_ns)
        return self._take()


def offline_verdicts(
    trial: Trial, model: VerifierModel, contradictions: Sequence[Contradiction] = ()
) -> list[Verdict]:
    """The verdicts of `trial` from one VerifierSession, fed as verify's offline features are
    (stream time from the first sample; each event before the first sample at or after it;
    the end event last): what verifier_node publishes for the trial's bag. `contradictions`
    (verify/mismatch.py) apply from their times, as the classifier's final verdicts do live."""
    session = VerifierSession(model)
    for c in contradictions:
        session.contradict(c)
    out: list[Verdict] = []
    for i, t, due in sample_steps(trial):
        for when, name in due:
            session.phase(name, when)
        for arm in model.arms:
            out += session.push(arm, t, trial.wrench[arm][i])
    return out + session.end()


def sample_steps(trial: Trial) -> Iterator[tuple[int, float, list[tuple[float, str]]]]:
    """(sample index, stream time from the first sample, the sub-task events (time, name) due
    before it) per sample, as a verifier is fed a trial: an event before the first sample at or
    after it; the end event is left to the caller."""
    t0 = float(trial.time[0])
    events = [(t - t0, n) for t, n in trial_phase_events(trial) if n != END_PHASE]
    k = 0
    for i, t in enumerate(np.asarray(trial.time, dtype=float) - t0):
        due = []
        while k < len(events) and events[k][0] <= t:
            due.append(events[k])
            k += 1
        yield i, float(t), due


def verifier_health(
    stream: VerifierStream | None,
    model_problem: str,
    model: tuple[str, str],
    latency: LatencyWindow,
    watch: CounterWatch,
    matched: tuple[int, int],
) -> list[Health]:
    """verifier_node's status: `model` (file, SHA-256), the sample-to-verdict latency of the
    period, rejected samples and events, the current health; `matched`: (verdict subscribers,
    intake publishers). ERROR without a usable verifier."""
    name = "verifier_node"
    if stream is None:
        return [Health(f"{name}: model", ERROR, f"no usable verifier: {model_problem}")]
    n, p50, p99 = latency.take()
    counts = {
        **{f"rejected samples {a}": c.rejected_total for a, c in stream.segmenter.counts.items()},
        "unknown events": stream.segmenter.unknown_phases,
        "late events": stream.segmenter.late_phases,
    }
    moved = watch.moved(counts)
    values = (
        ("verifier file", model[0]),
        ("verifier sha256", model[1]),
        ("health", stream.health),
        ("verdicts", str(stream.verdicts)),
        ("alarms", str(stream.alarms)),
        ("verdict batches in period", str(n)),
        ("sample to verdict p50 ms", f"{p50:.3f}"),
        ("sample to verdict p99 ms", f"{p99:.3f}"),
        ("verdict subscribers matched", str(matched[0])),
        ("intake publishers matched", str(matched[1])),
        *((k, str(v)) for k, v in counts.items()),
    )
    level = WARN if moved else OK
    message = f"health {stream.health}" + (f"; moved: {moved}" if moved else "")
    return [Health(f"{name}: verifier", level, message, values)]

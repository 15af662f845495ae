"""Classifier session: classifier_node's state without ROS (words and events in, beliefs out).

The node takes whatever DDS delivered (a burst) and hands it here in publication order; it
publishes what comes back. Here live: stream switching (words of a new stream issue the previous
stream's verdicts and start a new tracker session), the latched events of earlier streams
(live/join.LatchedEvents), the Words messages of one wrench sample (a belief once all of them are
in), proven word losses and /task_state (live/state.py StateFilter).

A classification follows every input that completes its wrench sample's messages, and every
applied sub-task event (once no sample's messages are half in), whatever the burst it came in:
the beliefs and /task_state are a function of the input sequence, so the offline replay
(live/replay.py), fed the same sequence, produces exactly what the node publishes.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass, field

from rcbht_introspection.live.belief import UNKNOWN, Belief, BeliefTracker
from rcbht_introspection.live.join import LatchedEvents
from rcbht_introspection.live.state import StateFilter
from rcbht_introspection.live.teach import Teacher, TeachRequest, TeachStatus
from rcbht_introspection.summaries.blocks import WrenchBlock
from rcbht_introspection.taxonomy.words import Level, Word

COUNTS = (
    "words lost",
    "sub-tasks judged unknown after a loss",
    "latched events of earlier streams dropped",
)
"""What a session counts (the classifier's /diagnostics values)."""
StreamKey = tuple[int, int]
"""(time origin ns, stream id): one segmenter stream."""


@dataclass(frozen=True)
class WordsInput:
    """One Words message as plain data."""

    arm: str
    level: Level
    words: list[Word]
    now: float
    """Stream time of the wrench sample that finalised the words."""
    stamp_ns: int
    """That sample's stamp: the messages of one batch share it."""
    stream: StreamKey
    batch_size: int
    """Messages of the batch (0: a watermark that only moves the level's numbering on)."""
    end_of_stream: bool
    seq_end: int
    wrench: tuple[WrenchBlock, ...] = ()
    """The arm's wrench blocks closed since its previous batch (on a batch's first message)."""


@dataclass(frozen=True)
class PhaseInput:
    """One applied sub-task event (rcbht/phase) as plain data."""

    name: str
    time: float
    stamp_ns: int
    stream: StreamKey
    published_ns: int | None = None
    """DDS source timestamp: tells latched history from live events."""


@dataclass
class Step:
    """What the node publishes after a call, in order."""

    beliefs: list[tuple[Belief, int]] = field(default_factory=list)
    """(belief, trigger stamp ns): per classification, the verdicts on finished sub-tasks, then
    the running belief."""
    states: list[tuple[float, str]] = field(default_factory=list)
    """(stream time, new /task_state) of each change, in order."""
    update_ms: list[float] = field(default_factory=list)
    """Time each classification took (the node's belief-update latency)."""
    lost: int = 0
    """Words newly proven lost (a late join or lost messages)."""
    ignored_events: list[str] = field(default_factory=list)
    """Sub-task event names the tracker does not know."""
    model_swapped: bool = False
    """A taught model was taken into use before these beliefs."""
    error: str = ""
    """A model prediction error new since the last step ('' when none)."""

    def notes(self) -> list[tuple[str, str]]:
        """What the node logs about this step: (level, line)."""
        out = [("warning", f"ignored unknown sub-task event {n!r}") for n in self.ignored_events]
        if self.lost:
            out.append(
                (
                    "warning",
                    f"{self.lost} words of this stream never arrived (joined late or lost): the "
                    f"sub-task under way is judged {UNKNOWN!r} until the next boundary",
                )
            )
        if self.error:
            out.append(("error", f"model prediction failed, publishing {UNKNOWN!r}: {self.error}"))
        return out


class ClassifierSession:
    """One classifier over successive streams: `receive` inputs (any bursts), beliefs come back."""

    def __init__(
        self,
        tracker: BeliefTracker,
        state: StateFilter,
        counts: dict[str, int] | None = None,
        teaching: Teacher | None = None,
    ) -> None:
        self.tracker = tracker
        self.teaching = teaching
        """Labelled windows -> taught models (learn/teaching.py); None: teaching is off."""
        self.state = state
        self.history: LatchedEvents[PhaseInput] = LatchedEvents()
        self.stream: StreamKey | None = None
        self.open: dict[tuple[str, int], tuple[int, int]] = {}
        """(arm, sample stamp) -> (messages received, batch size) of batches not yet complete."""
        self.passed: dict[str, int] = {}
        """Per arm, the stamp of its latest complete batch: earlier batches are done with."""
        self.trigger_ns: int | None = None
        """Earliest sample behind evidence not yet classified (the conservative latency)."""
        self._stale = 0
        self.reported_error: str | None = None
        self.counts = counts if counts is not None else {}
        """Losses and drops (a node passes its own dict: the counts outlive a reconfigure)."""
        for name in COUNTS:
            self.counts.setdefault(name, 0)

    def rejoin(self, now_ns: int) -> None:
        """The subscriptions were (re)created at `now_ns`: latched events before it are history."""
        self.history.rejoin(now_ns)

    def receive(self, items: Iterable[WordsInput | PhaseInput]) -> Step:
        """Take inputs in publication order (each topic is in order, the topics among themselves
        are not: the node sorts a burst by source timestamp); classify after each that completes
        a classification point (module doc)."""
        step = Step()
        for item in items:
            if isinstance(item, PhaseInput):
                self._phase(item, step)
            else:
                self._words(item, step)
            if self.trigger_ns is not None and not self.open:
                self._classify(step)
        self.counts["latched events of earlier streams dropped"] += self.history.stale - self._stale
        self._stale = self.history.stale
        error = self.tracker.last_error
        if error and error != self.reported_error:
            self.reported_error = step.error = error
        return step

    def teach(self, request: TeachRequest) -> TeachStatus:
        """A label for a window of the current stream (refused when teaching is off)."""
        if self.teaching is None:
            return TeachStatus(False, "teaching is off (parameter teach_enabled)", 0, 0, 0, 0)
        return self.teaching.request(request, self.tracker)

    def teach_topic(self, request: TeachRequest, topic: str) -> str:
        """A fire-and-forget label (the teach topic); what to warn about ('' when nothing): as
        the service, an empty label is refused, and counted."""
        if not request.label:
            self.counts["teach requests refused"] = self.counts.get("teach requests refused", 0) + 1
            return f"teach request refused: empty label on {topic}"
        status = self.teach(request)
        refused = not status.accepted and self.teaching is None
        return f"teach request refused: {status.message}" if refused else ""

    def _classify(self, step: Step) -> None:
        """Verdicts, belief and state from the evidence so far."""
        began = time.perf_counter()
        trigger, self.trigger_ns = self.trigger_ns or 0, None
        self._count_losses(step)
        if self.teaching is not None:
            model = self.teaching.take_model()
            if model is not None:  # a taught model: every belief from here on uses it
                self.tracker.set_model(model)
                step.model_swapped = True
        if self.teaching is not None and self.teaching.waiting:
            self.teaching.collect(self.tracker)  # before take_finals prunes words
        for final in self.tracker.take_finals():
            self._emit(step, final, trigger)
        belief = self.tracker.current()
        self._emit(step, belief, trigger)
        if self.state.update(self.tracker.now, belief):
            step.states.append((self.tracker.now, self.state.state))
        step.update_ms.append((time.perf_counter() - began) * 1e3)

    # --- input ---------------------------------------------------------------------------
    def _words(self, item: WordsInput, step: Step) -> None:
        self._enter(item.stream, step)
        self.tracker.add_wrench(item.arm, item.wrench)
        self.tracker.add_words(item.arm, item.words, item.now, item.level, item.seq_end)
        if item.batch_size == 0:  # only the level's word numbering moved on: no new evidence
            return
        if item.end_of_stream:
            self.tracker.end_of_stream(item.arm, item.level)
        arm, stamp = item.arm, item.stamp_ns
        if stamp <= self.passed.get(arm, -1):
            # a straggler of a batch this arm has passed (its topic delivered it after a later
            # batch's messages): its words count, it opens nothing
            self._trigger(stamp)
            return
        count, _ = self.open.get((arm, stamp), (0, item.batch_size))
        if count + 1 < item.batch_size:
            self.open[(arm, stamp)] = (count + 1, item.batch_size)
        else:  # complete: this arm's batches still open from before it will not complete
            # (lost, joined late, or their stragglers come later); the other arm's topics are
            # not ordered with this one's
            self.passed[arm] = stamp
            self.open = {k: v for k, v in self.open.items() if k[0] != arm or k[1] > stamp}
        self._trigger(stamp)

    def _phase(self, item: PhaseInput, step: Step) -> None:
        identity = (item.name, item.time)
        for event in self.history.event(
            item.stream, item, item.published_ns, self.stream, identity
        ):
            self._enter(item.stream, step)
            self._apply(event, step)

    def _enter(self, key: StreamKey, step: Step) -> None:
        """A live message of stream `key`: a new stream starts a new session (and its history)."""
        if key == self.stream:
            if not self.history.live:  # the first live message since a rejoin
                for event in self.history.stream_started(key):
                    self._apply(event, step)
            return
        if self.stream is not None and self.tracker.arms:
            # the previous stream ended without all its end markers: issue what it has
            for arm in tuple(self.tracker.arms):
                self.tracker.end_of_stream(arm)
            self._count_losses(step)
            for final in self.tracker.take_finals():
                self._emit(step, final, 0)
        if self.teaching is not None and self.teaching.waiting:
            self.teaching.collect(self.tracker, stream_ends=True)
        self.tracker.reset()
        self.state.new_stream()
        self.stream = key
        self.open, self.passed, self.trigger_ns = {}, {}, None
        for event in self.history.stream_started(key):  # its events the latched topic replayed
            self._apply(event, step)

    def _apply(self, event: PhaseInput, step: Step) -> None:
        if not self.tracker.phase(event.name, event.time):
            step.ignored_events.append(event.name)
            return
        self._trigger(event.stamp_ns)

    def _trigger(self, stamp: int) -> None:
        self.trigger_ns = stamp if self.trigger_ns is None else min(self.trigger_ns, stamp)

    # --- output --------------------------------------------------------------------------
    def _count_losses(self, step: Step) -> None:
        lost = self.tracker.account_losses()
        self.counts["words lost"] += lost
        step.lost += lost

    def _emit(self, step: Step, belief: Belief, trigger_ns: int) -> None:
        if belief.final and belief.blind:
            self.counts["sub-tasks judged unknown after a loss"] += 1
        step.beliefs.append((belief, trigger_ns))

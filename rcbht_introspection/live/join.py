"""Joining a running stream: which words never arrived, and which latched events still apply.

A classifier that starts (or restarts) while the segmenter runs misses the words published
before its subscriptions matched, and the latched `rcbht/phase` replays events of earlier
streams. Both are decided here, without ROS, so the classifier neither trusts a partial
sub-task nor re-judges finished trials.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Iterable, Sequence
from dataclasses import dataclass
from typing import Generic, TypeVar

from rcbht_introspection.taxonomy.words import LEVELS, Level, Word

E = TypeVar("E")

MAX_WORDS_PER_MESSAGE = 32
"""Most words in one Words message (~7 kB). Fast DDS keeps a publisher's and a subscriber's sample
buffers at the largest size each has carried; occasional whole-trial messages (100 kB at a
stream's end) made a node's memory grow for hours. Bounded messages keep it flat."""
MAX_BATCH_MESSAGES = 255
"""Words.batch_size is a uint8."""


class WordLedger:
    """The words of one arm's stream that arrived; a missing one is proven lost, never guessed.

    The segmenter numbers an arm's words 1, 2, 3, ... in release order, over all levels, and
    publishes each level on its own topic; each topic delivers in order. Once every level has
    delivered a word numbered n or more (or its end of stream), every word up to n has arrived
    or never will: numbers up to n not received are lost. A word still in flight on a slower
    topic is therefore never counted as lost.
    """

    def __init__(self) -> None:
        self.upto: dict[Level, float] = dict.fromkeys(LEVELS, 0)
        """Per level, the number up to which its topic has delivered every word it carries
        (a message's `seq_end`, infinite after the level's end of stream)."""
        self.top = 0
        """The highest number received."""
        self.open: dict[int, float] = {}
        """Received numbers above `settled` -> stream time at which they were released."""
        self.settled = 0
        """Every number up to this one is accounted for: received or lost."""
        self.lost = 0
        self.blind_until = -math.inf
        """Stream time up to which lost words may reach (the release of the next word received)."""

    def add(
        self, words: Iterable[Word], now: float, level: Level | None = None, seq_end: int = 0
    ) -> None:
        """Words received in one message of `level`, released at stream time `now`.

        `seq_end` is the arm's highest number when the message was published (Words.seq_end):
        every word of that level up to it has now arrived. Without it, each word's own number.
        """
        for w in words:
            if w.seq > self.upto[w.level]:
                self.upto[w.level] = w.seq
            if w.seq > self.settled:
                self.open[w.seq] = now
                self.top = max(self.top, w.seq)
        if level is not None and seq_end > self.upto[level]:
            self.upto[level] = seq_end

    def end(self, level: Level | None = None) -> None:
        """The stream ended on `level` (None: on every level)."""
        for lv in LEVELS if level is None else (level,):
            self.upto[lv] = math.inf

    @property
    def has_gap(self) -> bool:
        """Some number below the highest received one has neither arrived nor been proven lost."""
        return len(self.open) < self.top - self.settled

    def settle(self) -> int:
        """Prove what can be proven now; returns the number of words newly found lost."""
        bound = min(self.upto.values())
        if math.isinf(bound):
            bound = max(self.top, self.settled)
        if bound <= self.settled:
            return 0
        lost = 0
        previous = self.settled
        for seq in sorted(s for s in self.open if s <= bound):
            if seq > previous + 1:  # numbers previous+1 .. seq-1 never came
                lost += seq - previous - 1
                self.blind_until = max(self.blind_until, self.open[seq])
            previous = seq
            del self.open[seq]
        self.settled = int(bound)
        self.lost += lost
        return lost


class LatchedEvents(Generic[E]):
    """Sub-task events replayed from the latched topic at a join: only the running stream's apply.

    An event published before `since_ns` (the subscription's creation) is history. History of
    the stream that live messages come from applies; history of other streams is dropped and
    counted; history that comes before any live message waits for the first live stream.
    An event without a publication time (rclpy's EventsExecutor gives no DDS sample info) is
    taken as history until the first live message after the (re)join, and as live after it:
    the latched topic delivers its history at the match, before what is published later.
    """

    def __init__(self, since_ns: int = 0) -> None:
        self.since_ns = since_ns
        self.held: dict[Hashable, list[E]] = {}
        self.applied: set[tuple[Hashable, Hashable]] = set()
        """(stream, event identity) already applied: a re-activated node gets them again."""
        self.stale = 0
        """Events of earlier streams that the latched topic replayed and that were dropped."""
        self.live = True
        """A live message arrived since the last rejoin (events without a time are live)."""

    def rejoin(self, since_ns: int) -> None:
        """The subscriptions were (re)created at `since_ns`: what was published before is history."""
        self.since_ns = since_ns
        self.live = False

    def event(
        self,
        stream: Hashable,
        event: E,
        published_ns: int | None,
        current: Hashable | None,
        identity: Hashable = None,
    ) -> list[E]:
        """The events to apply now for one received event of `stream`.

        `identity` (e.g. name and stream time) recognises an event applied before: the latched
        topic replays the running stream's events to a node that was deactivated and activated.
        """
        key = (stream, event if identity is None else identity)
        if key in self.applied:
            return []
        history = published_ns < self.since_ns if published_ns else not self.live
        if not history or stream == current:
            self.applied.add(key)
            return [event]
        if current is None or not published_ns:
            self.held.setdefault(stream, []).append(event)
            self.applied.add(key)  # it applies, if at all, through stream_started
        else:
            self.stale += 1
        return []

    def stream_started(self, stream: Hashable) -> list[E]:
        """Live messages of `stream` arrive (a new stream, or the first live message since a
        rejoin): its held history applies, the rest is dropped."""
        self.live = True
        events = self.held.pop(stream, [])
        self.stale += sum(len(v) for v in self.held.values())
        self.held.clear()
        self.applied = {k for k in self.applied if k[0] == stream}  # older streams are done
        return events


class Watermarks:
    """Publisher side of the word numbering: each message's `seq_end`, and idle levels to mark.

    A level topic that had nothing to publish for `idle_s` while the arm's numbers moved on gets
    an empty message carrying the new highest number, so a subscriber proves its losses within
    about `idle_s` instead of at the next word of its slowest level (behaviours can take the
    whole trial).
    """

    def __init__(self, idle_s: float = 0.1) -> None:
        self.idle_s = idle_s
        self.highest: dict[str, tuple[int, int]] = {}
        """Per arm, (stream id, highest number released)."""
        self.marked: dict[tuple[str, Level], tuple[int, int, float]] = {}
        """Per (arm, level), (stream id, seq_end last published, when)."""
        self.ended_stream: dict[str, int] = {}
        """Per arm, the stream whose end-of-stream messages went out: nothing more to mark."""

    def batch(self, arm: str, stream_id: int, words: Iterable[Word]) -> int:
        """The arm's highest number once this batch is out (its messages' seq_end)."""
        stream, top = self.highest.get(arm, (stream_id, 0))
        if stream != stream_id:
            top = 0
        top = max([top, *(w.seq for w in words)])
        self.highest[arm] = (stream_id, top)
        return top

    def published(self, arm: str, stream_id: int, level: Level, seq_end: int, now: float) -> None:
        """A message of `level` carrying `seq_end` went out at `now` (seconds, any clock)."""
        self.marked[(arm, level)] = (stream_id, seq_end, now)

    def ended(self, arm: str, stream_id: int) -> None:
        """The arm's stream ended (its end-of-stream messages say all): nothing more to mark. Its
        highest number stays: a sample of that stream delivered after its end still gets a batch."""
        self.ended_stream[arm] = stream_id

    def due(self, now: float) -> list[tuple[str, int, Level, int]]:
        """(arm, stream id, level, seq_end) of the empty messages to publish now."""
        out = []
        for arm, (stream_id, top) in self.highest.items():
            if self.ended_stream.get(arm) == stream_id:
                continue
            for level in LEVELS:
                stream, seq_end, when = self.marked.get((arm, level), (stream_id, 0, -math.inf))
                if stream != stream_id:
                    seq_end = 0
                if top > seq_end and now - when >= self.idle_s:
                    out.append((arm, stream_id, level, top))
        return out


@dataclass(frozen=True)
class LevelMessage:
    """One Words message of a batch: some words of one level and what they prove."""

    level: Level
    words: list[Word]
    seq_end: int
    """Every word of this level numbered up to this one is in this message or an earlier one."""
    end_of_stream: bool
    """The last message of this level's stream."""


def batch_messages(
    words: Sequence[Word],
    top: int,
    end_of_stream: bool = False,
    max_words: int = MAX_WORDS_PER_MESSAGE,
) -> list[LevelMessage]:
    """The Words messages of one batch, level by level: at most `max_words` words each.

    Levels without words get no message, except at the end of a stream (every level says it
    ended). The last piece of a level carries the batch's `top` (Watermarks.batch); an earlier
    piece carries only the numbers below the next piece's, so a subscriber that settles between
    pieces never counts a word of a later piece as lost. `max_words` grows if the batch would
    need more than MAX_BATCH_MESSAGES messages.
    """
    per_level = {level: [w for w in words if w.level == level] for level in LEVELS}
    levels = [lv for lv in LEVELS if per_level[lv] or end_of_stream]
    while sum(max(1, math.ceil(len(per_level[lv]) / max_words)) for lv in levels) > (
        MAX_BATCH_MESSAGES
    ):
        max_words *= 2
    out = []
    for level in levels:
        level_words = per_level[level]
        pieces = [level_words[i : i + max_words] for i in range(0, len(level_words), max_words)]
        pieces = pieces or [[]]
        for i, piece in enumerate(pieces):
            last = i == len(pieces) - 1
            seq_end = top if last else min(w.seq for p in pieces[i + 1 :] for w in p) - 1
            out.append(LevelMessage(level, piece, seq_end, end_of_stream and last))
    return out

"""Joining a running stream: which words never arrived, and which latched events still apply.

A classifier that starts (or restarts) while the segmenter runs misses the words published
before its subscriptions matched, and the latched `rcbht/phase` replays events of earlier
streams. Both are decided here, without ROS, so the classifier neither trusts a partial
sub-task nor re-judges finished trials.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Iterable
from typing import Generic, TypeVar

from rcbht_introspection.taxonomy.words import LEVELS, Level, Word

E = TypeVar("E")


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
        """Per level, the highest word number received on it (infinite after its end of stream)."""
        self.open: dict[int, float] = {}
        """Received numbers above `settled` -> stream time at which they were released."""
        self.settled = 0
        """Every number up to this one is accounted for: received or lost."""
        self.lost = 0
        self.blind_until = -math.inf
        """Stream time up to which lost words may reach (the release of the next word received)."""

    def add(self, words: Iterable[Word], now: float) -> None:
        """Words received in one message, released at stream time `now`."""
        for w in words:
            if w.seq > self.upto[w.level]:
                self.upto[w.level] = w.seq
            if w.seq > self.settled:
                self.open[w.seq] = now

    def end(self, level: Level | None = None) -> None:
        """The stream ended on `level` (None: on every level)."""
        for lv in LEVELS if level is None else (level,):
            self.upto[lv] = math.inf

    @property
    def has_gap(self) -> bool:
        """Some number below the highest received one has neither arrived nor been proven lost."""
        return bool(self.open) and len(self.open) < max(self.open) - self.settled

    def settle(self) -> int:
        """Prove what can be proven now; returns the number of words newly found lost."""
        bound = min(self.upto.values())
        if math.isinf(bound):
            bound = max(self.open, default=self.settled)
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
    """

    def __init__(self, since_ns: int) -> None:
        self.since_ns = since_ns
        self.held: dict[Hashable, list[E]] = {}
        self.stale = 0
        """Events of earlier streams that the latched topic replayed and that were dropped."""

    def event(
        self, stream: Hashable, event: E, published_ns: int | None, current: Hashable | None
    ) -> list[E]:
        """The events to apply now for one received event of `stream`."""
        if not published_ns or published_ns >= self.since_ns or stream == current:
            return [event]
        if current is None:
            self.held.setdefault(stream, []).append(event)
        else:
            self.stale += 1
        return []

    def stream_started(self, stream: Hashable) -> list[E]:
        """Live messages of `stream` arrive: its held history applies, the rest is dropped."""
        events = self.held.pop(stream, [])
        self.stale += sum(len(v) for v in self.held.values())
        self.held.clear()
        return events

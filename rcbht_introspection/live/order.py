"""Publication order of what a node received: the one place where the nodes order their inputs.

Each topic delivers in order; the topics among themselves do not. rclpy's SingleThreadedExecutor
serves the ready subscriptions in a fixed order, so a node collects what one wake-up delivered
(`Arrivals.add`, with the DDS source timestamp of each message) and hands it on sorted by it
(`release`): an event before the samples published after it, the classifier's inputs in
publication order. Without source timestamps (rclpy's EventsExecutor gives none) the order is
the arrival order, which that executor keeps over all of a node's subscriptions. What arrives
after later-published inputs across a release (a late event, a straggler of a batch) is the
sessions' to place: live/segmenter.py (late and end events by source timestamp),
live/classifier.py (stragglers, latched history: live/join.py).
"""

from __future__ import annotations

from typing import Generic, TypeVar

T = TypeVar("T")


class Arrivals(Generic[T]):
    """Inputs received since the last `release`, each with its source timestamp or None."""

    def __init__(self) -> None:
        self.items: list[tuple[int | None, T]] = []

    def add(self, source_ns: int | None, item: T) -> None:
        """One received input (`source_ns`: the publisher's DDS source timestamp, if known)."""
        self.items.append((source_ns, item))

    def release(self) -> list[tuple[int | None, T]]:
        """Everything added since the last release, in publication order: sorted by source
        timestamp when every input has one (stable, so each topic keeps its own order), else as
        it arrived."""
        items, self.items = self.items, []
        if len(items) > 1 and all(source is not None for source, _ in items):
            items.sort(key=lambda pair: pair[0] or 0)
        return items

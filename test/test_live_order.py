"""The nodes' input order (live/order.py) and what the sessions do with inputs that cross a burst:
out-of-order delivery across topics, a burst boundary between two arms' topics, a late end event.
The node only adapts messages; these are the ordering guarantees, without ROS."""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np

from rcbht_introspection.live.order import Arrivals
from rcbht_introspection.live.segmenter import Output, SegmenterSession, arm_stream_factory
from rcbht_introspection.taxonomy.words import Word

ORIGIN_NS = 1_700_000_000 * 10**9
PERIOD_NS = 5_000_000
ARMS = ("L", "R")


def test_a_burst_is_released_in_publication_order_each_topic_in_its_own() -> None:
    """Topics delivered out of order among themselves come out by source timestamp; inputs with
    equal timestamps keep their arrival order."""
    arrivals: Arrivals[str] = Arrivals()
    for source, item in ((30, "R3"), (40, "R4"), (10, "L1"), (35, "event"), (30, "L3"), (20, "L2")):
        arrivals.add(source, item)
    assert [item for _, item in arrivals.release()] == ["L1", "L2", "R3", "L3", "event", "R4"]
    assert arrivals.release() == []


def test_without_source_timestamps_the_arrival_order_stands() -> None:
    """The EventsExecutor gives no source timestamps: arrival order (one queue over all topics);
    an input with a timestamp among ones without sorts nothing either."""
    arrivals: Arrivals[str] = Arrivals()
    for source, item in ((None, "b"), (None, "a"), (5, "c")):
        arrivals.add(source, item)
    assert [item for _, item in arrivals.release()] == ["b", "a", "c"]


def _wrench(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    knots = np.linspace(0, n, 10)
    cols = [np.interp(np.arange(n), knots, rng.normal(0, 5, 10)) for _ in range(6)]
    return np.column_stack(cols) + rng.normal(0, 0.02, (n, 6))


Message = tuple[int, str, object]
"""(source ns, arm ('' for an event), event name or (stamp ns, wrench))."""


def _published(n: int, events: dict[int, str]) -> list[Message]:
    """Two arms' samples in publication order (L then R each period), an event after both arms'
    sample i for each i in `events`."""
    wrench = {arm: _wrench(n, seed) for seed, arm in enumerate(ARMS)}
    out: list[Message] = []
    for i in range(n):
        for k, arm in enumerate(ARMS):
            out.append((10 * i + k, arm, (ORIGIN_NS + i * PERIOD_NS, wrench[arm][i])))
        if i in events:
            out.append((10 * i + 5, "", events[i]))
    return out


def _feed(
    bursts: Sequence[Sequence[Message]],
) -> tuple[dict[str, list[Word]], list[tuple[str, float]]]:
    """The bursts through Arrivals into one two-arm session; its words per arm and events."""
    session = SegmenterSession(ARMS, arm_stream_factory(), hold_s=0.2, max_hold_s=10.0)
    words: dict[str, list[Word]] = {arm: [] for arm in ARMS}
    phases: list[tuple[str, float]] = []

    def take(out: Output) -> None:
        for batch in out.batches:
            words[batch.arm].extend(batch.words)
        phases.extend((p.name, p.time) for p in out.phases)

    for burst in bursts:
        arrivals: Arrivals[tuple[str, object]] = Arrivals()
        for source, arm, payload in burst:
            arrivals.add(source, (arm, payload))
        for source, (arm, payload) in arrivals.release():
            if isinstance(payload, str):
                take(session.phase(payload, source))
            else:
                stamp, values = payload
                take(session.push(arm, stamp, values, source))
    last = max(source for burst in bursts for source, _, _ in burst)
    take(session.flush(last + 10**10))  # the end event has no later sample
    return words, phases


def _shuffled_topics(messages: list[Message], seed: int) -> Iterator[list[Message]]:
    """Bursts as an executor cuts them: each topic in order, the topics interleaved at random."""
    rng = np.random.default_rng(seed)
    queues = {key: [m for m in messages if m[1] == key] for key in ("", *ARMS)}
    while any(queues.values()):
        burst: list[Message] = []
        for _ in range(int(rng.integers(1, 12))):
            ready = [k for k, q in queues.items() if q]
            if not ready:
                break
            burst.append(queues[ready[int(rng.integers(len(ready)))]].pop(0))
        yield burst


def test_out_of_order_topics_and_burst_boundaries_between_arms_give_the_same_words() -> None:
    """Samples of the two arms and the events, delivered with each topic in order but the topics
    interleaved at random and cut into bursts (an arm's samples in the next burst after the
    event published after them): the same words and event placements as in publication order."""
    messages = _published(600, {100: "approach", 250: "rotation", 400: "insertion"})
    expected = _feed([messages])
    assert [name for name, _ in expected[1]] == ["approach", "rotation", "insertion"]
    for seed in range(5):
        assert _feed(list(_shuffled_topics(messages, seed))) == expected


def test_a_late_end_event_waits_for_the_samples_published_before_it() -> None:
    """The end event delivered in a burst before the last samples of one arm (published before
    it): it is applied after them, so that arm's stream ends at its last sample."""
    messages = _published(300, {50: "approach", 299: "done"})
    expected = _feed([messages])
    end = next(m for m in messages if m[2] == "done")
    lagging = [m for m in messages if m[1] == "L" and m[0] > 10 * 290]
    early = [m for m in messages if m not in lagging]
    assert (
        _feed([early[: early.index(end) + 1], lagging, early[early.index(end) + 1 :]]) == expected
    )
    assert expected[1][-1] == ("done", (299 * PERIOD_NS) / 1e9)

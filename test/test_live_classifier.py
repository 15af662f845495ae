"""The classifier node's protocol without DDS (live/classifier.py): batches, streams, latched events.

Bursts against one-by-one input on real trials: test_live_replay.py."""

from __future__ import annotations

from rcbht_introspection.live.belief import UNKNOWN, Belief, BeliefTracker
from rcbht_introspection.live.classifier import ClassifierSession, PhaseInput, Step, WordsInput
from rcbht_introspection.live.state import StateFilter
from rcbht_introspection.taxonomy.words import LEVELS, Level, Word

ORIGIN = 1_000_000_000
STREAM = (ORIGIN, 0)
NEXT_STREAM = (ORIGIN + 60_000_000_000, 1)


def _session() -> ClassifierSession:
    return ClassifierSession(BeliefTracker(None), StateFilter())


def _words(
    level: Level,
    seqs: list[int],
    t: float,
    batch_size: int,
    stream: tuple[int, int] = STREAM,
    end: bool = False,
    seq_end: int | None = None,
) -> WordsInput:
    words = [Word("Fz", level, "cons", t - 0.1, t, arm="R", seq=s) for s in seqs]
    return WordsInput(
        arm="R",
        level=level,
        words=words,
        now=t,
        stamp_ns=stream[0] + round(t * 1e9),
        stream=stream,
        batch_size=batch_size,
        end_of_stream=end,
        seq_end=max(seqs, default=0) if seq_end is None else seq_end,
    )


def _phase(
    name: str, t: float, stream: tuple[int, int] = STREAM, published: int | None = None
) -> PhaseInput:
    return PhaseInput(name, t, stream[0] + round(t * 1e9), stream, published)


def test_a_belief_waits_for_every_message_of_the_sample() -> None:
    session = _session()
    [(empty, trigger)] = session.receive([_phase("approach", 0.0)]).beliefs
    assert trigger == STREAM[0] and empty.n_words == 0  # the event alone: a window without words
    first = _words(Level.PRIMITIVE, [1, 2], 1.0, batch_size=3)
    second = _words(Level.PRIMITIVE, [3], 1.0, batch_size=3)  # a second piece of the level
    third = _words(Level.COMPOSITION, [4], 1.0, batch_size=3)
    assert session.receive([first, second]).beliefs == []
    [(belief, trigger)] = session.receive([third]).beliefs
    assert trigger == first.stamp_ns
    assert belief.subtask == UNKNOWN and belief.n_words == 4


def test_an_event_waits_for_the_batch_in_flight_and_a_lost_piece_blocks_no_later_sample() -> None:
    session = _session()
    session.receive([_phase("approach", 0.0)])
    first = _words(Level.PRIMITIVE, [1], 1.0, batch_size=2)
    # the second piece of sample 1.0 never comes; an event and then sample 1.1 do
    assert session.receive([first, _phase("rotation", 1.0)]).beliefs == []
    later = _words(Level.PRIMITIVE, [3], 1.1, batch_size=1)
    [(belief, trigger)] = session.receive([later]).beliefs
    assert trigger == first.stamp_ns  # the earliest sample behind the evidence
    assert belief.phase == "rotation" and belief.n_words == 2  # both words reach t=1.0


def test_a_complete_batch_of_one_arm_does_not_drop_the_other_arm_s_batch_in_flight() -> None:
    """Arms publish on topics of their own: L's batch completing says nothing about R's."""
    session = _session()
    session.receive([_phase("approach", 0.0)])
    r_first = _words(Level.PRIMITIVE, [1], 1.0, batch_size=2)
    left = WordsInput(**{**vars(_words(Level.PRIMITIVE, [1], 1.0, batch_size=1)), "arm": "L"})
    r_second = _words(Level.COMPOSITION, [2], 1.0, batch_size=2)
    assert [b.n_words for b, _ in session.receive([r_first, left]).beliefs] == []
    [(belief, _)] = session.receive([r_second]).beliefs  # R's batch completes: a belief
    assert belief.n_words == 3


def test_a_straggler_of_a_passed_batch_counts_and_blocks_nothing() -> None:
    """A batch's message that its topic delivers after a later batch of the arm completed (a
    burst boundary between topics): its words count and the end of the stream is classified."""
    session = _session()
    session.receive([_phase("approach", 0.0)])
    first = _words(Level.PRIMITIVE, [1], 1.0, batch_size=2)
    later = _words(Level.PRIMITIVE, [3], 1.1, batch_size=1)
    assert len(session.receive([first, later]).beliefs) == 1
    straggler = _words(Level.COMPOSITION, [2], 1.0, batch_size=2)
    [(belief, _)] = session.receive([straggler]).beliefs
    assert belief.n_words == 3 and session.open == {}
    end = _words(Level.BEHAVIOR, [4], 1.2, batch_size=1, end=True)
    assert len(session.receive([end]).beliefs) == 1


def test_a_watermark_moves_numbering_on_but_is_no_evidence() -> None:
    session = _session()
    step = session.receive([_words(Level.BEHAVIOR, [], 1.0, batch_size=0, seq_end=7)])
    assert step.beliefs == []
    assert session.tracker.ledgers["R"].upto[Level.BEHAVIOR] == 7


def test_words_of_a_new_stream_issue_the_previous_streams_verdicts() -> None:
    session = _session()
    session.receive([_phase("approach", 0.0), _words(Level.PRIMITIVE, [1], 1.0, batch_size=1)])
    assert session.receive([_phase("rotation", 1.0)]).beliefs
    step = session.receive([_words(Level.PRIMITIVE, [1], 0.5, batch_size=1, stream=NEXT_STREAM)])
    finals = [(b, trigger) for b, trigger in step.beliefs if b.final]
    assert [b.phase for b, _ in finals] == ["approach"]  # rotation never ended: no verdict
    assert all(trigger == 0 for _, trigger in finals)
    assert session.stream == NEXT_STREAM and session.tracker.segments == []


def test_latched_events_of_an_earlier_stream_are_dropped_and_counted() -> None:
    session = _session()
    session.rejoin(now_ns=500)
    # replayed by the latched topic: published before the subscription existed
    old = _phase("approach", 0.0, stream=STREAM, published=100)
    running = _phase("approach", 0.0, stream=NEXT_STREAM, published=200)
    session.receive([old, running])
    assert session.tracker.segments == []  # no live message yet: which stream runs is unknown
    session.receive([_words(Level.PRIMITIVE, [1], 0.5, batch_size=1, stream=NEXT_STREAM)])
    assert [s.phase for s in session.tracker.segments] == ["approach"]
    assert session.counts["latched events of earlier streams dropped"] == 1


def test_latched_events_without_publication_times_wait_for_the_first_live_message() -> None:
    """Under the EventsExecutor events come without a DDS source timestamp: until a live message
    arrives after the join they are history (the running stream's apply, others are dropped);
    after it, an event of a new stream is live and starts that stream."""
    session = _session()
    session.rejoin(now_ns=500)
    old = _phase("approach", 0.0, stream=STREAM)
    running = _phase("approach", 0.0, stream=NEXT_STREAM)
    session.receive([old, running])
    assert session.tracker.segments == []
    session.receive([_words(Level.PRIMITIVE, [1], 0.5, batch_size=1, stream=NEXT_STREAM)])
    assert [s.phase for s in session.tracker.segments] == ["approach"]
    assert session.counts["latched events of earlier streams dropped"] == 1
    third = (NEXT_STREAM[0] + 60_000_000_000, 2)
    session.receive([_phase("approach", 0.0, stream=third)])  # live: the next stream begins
    assert session.stream == third


def test_a_reactivated_session_applies_the_running_streams_untimed_history_once() -> None:
    """Deactivate/activate (rejoin) with the same stream running: its replayed events are not
    applied twice, an older stream's are dropped at the first live message."""
    session = _session()
    session.receive([_phase("approach", 0.0), _words(Level.PRIMITIVE, [1], 0.5, batch_size=1)])
    session.rejoin(now_ns=500)
    older = (ORIGIN - 60_000_000_000, 9)
    session.receive([_phase("approach", 0.0), _phase("approach", 0.0, stream=older)])
    session.receive([_phase("rotation", 1.0)])  # the running stream's: applied at once
    session.receive([_words(Level.PRIMITIVE, [2], 1.5, batch_size=1)])
    assert [s.phase for s in session.tracker.segments] == ["approach", "rotation"]
    assert session.counts["latched events of earlier streams dropped"] == 1


def test_lost_words_are_counted_and_blind_the_sub_task() -> None:
    session = _session()
    session.receive([_phase("approach", 0.0)])
    # words 1..3 were published before this classifier matched
    late = [
        _words(level, [4] if level == Level.PRIMITIVE else [], 2.0, 1, seq_end=4)
        for level in LEVELS
    ]
    step = session.receive(late)
    assert step.lost == 3
    assert session.counts["words lost"] == 3
    assert step.beliefs[-1][0].blind


def test_an_unknown_event_is_reported_not_applied() -> None:
    """A name outside the tracker's sub-tasks (a model's task) is reported and not applied."""
    session = ClassifierSession(BeliefTracker(None, subtasks=("approach",)), StateFilter())
    step: Step = session.receive([_phase("wobble", 0.0)])
    assert step.ignored_events == ["wobble"] and session.tracker.segments == []


def test_a_new_stream_keeps_the_state_until_its_first_confident_belief() -> None:
    """A new stream is a sub-task boundary like the others: no flip to unknown without evidence."""
    session = ClassifierSession(BeliefTracker(None), StateFilter())
    # the previous stream's state: a belief without probabilities counts as certain
    assert session.state.update(9.0, Belief("approach", (), (), 0.0, 9.0, "boundary", n_words=5))
    step = session.receive(
        [_phase("approach", 0.0), _words(Level.PRIMITIVE, [1], 1.0, batch_size=1)]
    )
    assert step.beliefs and step.states == [] and session.state.state == "approach"
    session.state.update(2.0, Belief(UNKNOWN, (), (), 0.0, 2.0, "boundary", blind=True))
    assert session.state.state == UNKNOWN  # only proven losses make it unknown at once

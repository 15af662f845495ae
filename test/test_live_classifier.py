"""The classifier node's protocol without DDS (live/classifier.py): batches, streams, latched events."""

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
    session.receive([_phase("approach", 0.0)])
    first = _words(Level.PRIMITIVE, [1, 2], 1.0, batch_size=3)
    second = _words(Level.PRIMITIVE, [3], 1.0, batch_size=3)  # a second piece of the level
    third = _words(Level.COMPOSITION, [4], 1.0, batch_size=3)
    session.receive([first, second])
    assert session.classify() is None
    session.receive([third])
    step = session.classify()
    assert step is not None
    [(belief, trigger)] = step.beliefs
    assert trigger == STREAM[0]  # the event at t=0 is the earliest evidence behind it
    assert belief.subtask == UNKNOWN and belief.n_words == 4
    assert session.classify() is None  # nothing new


def test_a_watermark_moves_numbering_on_but_is_no_evidence() -> None:
    session = _session()
    session.receive([_words(Level.BEHAVIOR, [], 1.0, batch_size=0, seq_end=7)])
    assert session.classify() is None
    assert session.tracker.ledgers["R"].upto[Level.BEHAVIOR] == 7


def test_words_of_a_new_stream_issue_the_previous_streams_verdicts() -> None:
    session = _session()
    session.receive([_phase("approach", 0.0), _words(Level.PRIMITIVE, [1], 1.0, batch_size=1)])
    session.receive([_phase("rotation", 1.0)])
    assert session.classify() is not None
    step = session.receive([_words(Level.PRIMITIVE, [1], 0.5, batch_size=1, stream=NEXT_STREAM)])
    finals = [b for b, trigger in step.beliefs if b.final]
    assert [b.phase for b in finals] == ["approach"]  # rotation never ended: no verdict
    assert all(trigger == 0 for _, trigger in step.beliefs)
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


def test_lost_words_are_counted_and_blind_the_sub_task() -> None:
    session = _session()
    session.receive([_phase("approach", 0.0)])
    # words 1..3 were published before this classifier matched
    late = [
        _words(level, [4] if level == Level.PRIMITIVE else [], 2.0, 1, seq_end=4)
        for level in LEVELS
    ]
    session.receive(late)
    step = session.classify()
    assert step is not None and step.lost == 3
    assert session.counts["words lost"] == 3
    assert step.beliefs[-1][0].blind


def test_an_unknown_event_is_reported_not_applied() -> None:
    """A name outside the tracker's sub-tasks (a model's task) is reported and not applied."""
    session = ClassifierSession(BeliefTracker(None, subtasks=("approach",)), StateFilter())
    step: Step = session.receive([_phase("wobble", 0.0)])
    assert step.ignored_events == ["wobble"] and session.tracker.segments == []


def test_a_new_stream_reports_the_state_unknown_once() -> None:
    session = ClassifierSession(BeliefTracker(None), StateFilter())
    # the previous stream's state: a belief without probabilities counts as certain
    assert session.state.update(9.0, Belief("approach", (), (), 0.0, 9.0, "boundary"))
    session.receive([_phase("approach", 0.0), _words(Level.PRIMITIVE, [1], 1.0, batch_size=1)])
    step = session.classify()
    assert step is not None and step.state == UNKNOWN
    session.receive([_words(Level.PRIMITIVE, [2], 1.1, batch_size=1)])
    step = session.classify()
    assert step is not None and step.state is None

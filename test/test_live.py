"""The live pipeline's pure state: sub-task verdicts from words, and the segmenter session."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest
from conftest import SOURCES, trial_folders

from rcbht_introspection.io.trial import Trial
from rcbht_introspection.live.belief import UNKNOWN, BeliefTracker
from rcbht_introspection.taxonomy.words import LEVELS, Level, Word

if TYPE_CHECKING:
    from rcbht_introspection.live.segmenter import SegmenterSession


def words_of(trial: Trial) -> list[Word]:
    """Batch-engine words of a trial in end-time order (as a stream would deliver them)."""
    from rcbht_introspection.taxonomy.batch import label_trial

    tw = label_trial(trial)
    out = [w for per_level in tw.words.values() for per_axis in per_level.values()
           for seq in per_axis.values() for w in seq]  # fmt: skip
    return sorted(out, key=lambda w: (w.end, LEVELS.index(w.level)))


@pytest.fixture(scope="module", params=SOURCES)
def case(request: pytest.FixtureRequest) -> tuple[object, Path]:
    """A model trained on 15 REAL trials (golden words) and held-out REAL S-43, or a model trained
    on 5 generated trials (engine words) and a held-out generated trial."""
    from rcbht_introspection.learn.data import load_samples
    from rcbht_introspection.learn.models import train_model

    names = [f"20121127-HIROSA-S-{i:02d}" for i in (*range(1, 16), 43)]
    *folders, held_out = trial_folders(request, request.param, names, [0, 1, 2, 3, 4, 7])
    return train_model(load_samples(folders, words="auto")), held_out


def test_final_verdicts_equal_offline_classification(case: tuple[object, Path]) -> None:
    """Fed words in time order, the tracker's verdicts equal predict() on the spec 2.7 split."""
    from rcbht_introspection.grammar.split import split_words
    from rcbht_introspection.io.hiro import read_trial
    from rcbht_introspection.live.offline import trial_words

    trained, held_out = case
    trial = read_trial(held_out)
    words = words_of(trial)
    tracker = BeliefTracker(trained)
    assert tracker.current().subtask == UNKNOWN  # before any evidence
    events = [(t, s) for s, t, _ in trial.subtask_bounds()] + [(trial.end_time, "done")]
    finals = []
    i = 0
    for w in words:
        while i < len(events) and events[i][0] <= w.start:
            tracker.phase(events[i][1], events[i][0])
            i += 1
        tracker.add_words(w.arm, [w], w.end)
        for f in tracker.take_finals():
            # issued only once every word overlapping the sub-task is final
            assert all(x.start >= f.end or x.end >= f.end for x in words if x.end > w.end)
            finals.append(f)
    for t, name in events[i:]:
        tracker.phase(name, t)
    tracker.end_of_stream("R")
    finals += tracker.take_finals()
    assert [f.phase for f in finals] == [s for s, _, _ in trial.subtask_bounds()]
    assert all(f.final for f in finals)
    samples = split_words(trial_words(trial.name, {"R": words}), trial.state_times, trial.end_time)
    assert [f.subtask for f in finals] == trained.predict_samples(samples)
    assert tracker.finished
    held = tracker.current()  # the last verdict holds after the task ended
    assert (held.subtask, held.start, held.end, held.final) == (
        finals[-1].subtask, finals[-1].start, finals[-1].end, False,
    )  # fmt: skip


def test_window_mode_and_no_model() -> None:
    tracker = BeliefTracker(None, mode="window", window_s=1.0)
    w = Word("Fz", Level.PRIMITIVE, "bpos", 0.0, 0.4, arm="R")
    tracker.add_words("R", [w], 0.4)
    b = tracker.current()
    assert (b.subtask, b.n_words, b.start, b.end) == (UNKNOWN, 1, 0.0, 0.4)
    tracker.add_words("R", [Word("Fz", Level.PRIMITIVE, "cons", 0.4, 2.0, arm="R")], 2.0)
    b = tracker.current()
    assert (b.start, b.end, b.n_words) == (1.0, 2.0, 1)
    assert tracker.take_finals() == []  # no sub-tasks in window mode
    with pytest.raises(ValueError, match="mode"):
        BeliefTracker(None, mode="psychic")


def _stream_trial() -> Trial:
    rng = np.random.default_rng(11)
    t = np.round(np.arange(0.0, 4.0, 0.005), 6)
    knots = np.linspace(0, 4, 12)
    wrench = np.column_stack([np.interp(t, knots, rng.normal(0, 5, 12)) for _ in range(6)])
    return Trial("stream", t, {"R": wrench + rng.normal(0, 0.02, wrench.shape)},
                 state_times=(0.0, 1.2, 1.6, 2.5))  # fmt: skip


ORIGIN_NS = 1_700_000_000 * 10**9


def _session_with_stamps() -> tuple[Trial, Callable[..., object], SegmenterSession, np.ndarray]:
    """The synthetic trial, its stream factory, a one-arm session and the samples' stamps (ns)."""
    from rcbht_introspection.live.segmenter import SegmenterSession, arm_stream_factory

    trial = _stream_trial()
    factory = arm_stream_factory()
    ns = ORIGIN_NS + np.rint(trial.time * 1e9).astype(np.int64)
    return trial, factory, SegmenterSession(("R",), factory), ns


def _last_sample_before(events: list[tuple[float, str]], ns: np.ndarray) -> list[int]:
    """Index of the last sample at or before each event's time."""
    return [
        int(np.searchsorted(ns - ORIGIN_NS, round(t * 1e9), side="right")) - 1 for t, _ in events
    ]


def test_session_orders_events_by_source_time() -> None:
    """An event that arrives before samples published ahead of it still applies after them."""
    from rcbht_introspection.io.bags import END_PHASE, trial_phase_events
    from rcbht_introspection.live.offline import offline_stream_words

    trial, factory, session, ns = _session_with_stamps()
    events = trial_phase_events(trial, END_PHASE)
    # the publisher sends sample i at source time 10*i and an event right after the last sample
    # before it (source 10*i + 5); the session receives each event two samples early
    follows = _last_sample_before(events, ns)
    got: list[Word] = []
    applied = []

    def take(out: object) -> None:
        got.extend(w for b in out.batches for w in b.words)  # type: ignore[attr-defined]
        applied.extend(out.phases)  # type: ignore[attr-defined]

    for i in range(len(ns)):
        for (_, name), j in zip(events, follows, strict=True):
            if max(j - 2, 0) == i:
                take(session.phase(name, source_ns=10 * j + 5))
        take(session.push("R", int(ns[i]), trial.wrench["R"][i], source_ns=10 * i))
    take(session.flush(10 * len(ns) + 10**9))  # the end event has no later sample
    assert [p.name for p in applied] == [name for _, name in events]
    np.testing.assert_allclose([p.time for p in applied], [t for t, _ in events], atol=1e-9)
    assert got == offline_stream_words(trial, factory, END_PHASE)["R"]
    assert session.stream_id == 1 and session.late_phases == 0  # the end event closed stream 0


def test_an_event_is_published_between_its_samples_words_and_the_next_ones() -> None:
    """An event waits for the next sample, so one output can hold the boundary's words, the
    event and that sample's words (about 1 event in 9 on REAL): the event goes out after the
    words of the sample it is placed at and before the next sample's; an end event after the
    stream's last words and before the next stream's."""
    from rcbht_introspection.live.join import Watermarks
    from rcbht_introspection.live.publication import WordsOut, publication
    from rcbht_introspection.live.segmenter import Output, PhaseEvent, WordBatch

    def batch(stamp: int, seq: int, stream: int = 0, end: bool = False) -> WordBatch:
        word = Word("Fz", Level.PRIMITIVE, "cons", 0.0, stamp / 1e9, arm="R", seq=seq)
        return WordBatch("R", [word], ORIGIN_NS + stamp, ORIGIN_NS, stream, end_of_stream=end)

    def order(out: Output) -> list[tuple[str, int, int]]:
        return [
            ("event", x.stream_id, x.stamp_ns - ORIGIN_NS)
            if isinstance(x, PhaseEvent)
            else ("words", x.batch.stream_id, x.batch.stamp_ns - ORIGIN_NS)
            for x in publication(out, Watermarks())
            if isinstance(x, PhaseEvent) or x.message.words
        ]

    rotation = PhaseEvent("rotation", 5e-3, ORIGIN_NS + 5, ORIGIN_NS, 0, end=False)
    out = Output([batch(5, 1), batch(6, 2)], [rotation])  # the boundary's words, sample 6's
    assert order(out) == [("words", 0, 5), ("event", 0, 5), ("words", 0, 6)]
    done = PhaseEvent("done", 9e-3, ORIGIN_NS + 9, ORIGIN_NS, 0, end=True)
    out = Output([batch(9, 3, end=True), batch(1, 1, stream=1)], [done])
    assert order(out) == [("words", 0, 9), ("event", 0, 9), ("words", 1, 1)]
    assert all(
        isinstance(x, WordsOut) for x in publication(Output([batch(1, 1)], []), Watermarks())
    )


def test_a_batch_after_its_streams_end_keeps_an_unsigned_seq_end() -> None:
    """A second end-of-stream batch of an ended stream (seen once in a soak beside a busy loop)
    carries the stream's highest number, never a negative one (Words.seq_end is uint64: -1 made
    rclpy's publish fail and the segmenter exit), and the ended stream gets no idle watermarks."""
    from rcbht_introspection.live.join import Watermarks
    from rcbht_introspection.live.publication import WordsOut, publication
    from rcbht_introspection.live.segmenter import Output, WordBatch

    word = Word("Fz", Level.PRIMITIVE, "cons", 0.0, 9e-9, arm="R", seq=3)
    marks = Watermarks(idle_s=0.0)
    publication(
        Output([WordBatch("R", [word], ORIGIN_NS + 9, ORIGIN_NS, 0, end_of_stream=True)], []), marks
    )
    late = publication(
        Output([WordBatch("R", [], ORIGIN_NS + 9, ORIGIN_NS, 0, end_of_stream=True)], []),
        marks,
        1.0,
    )
    tops = [x.message.seq_end for x in late if isinstance(x, WordsOut)]
    assert tops and all(t == 3 for t in tops)
    assert marks.due(2.0) == []


def test_an_arm_ends_a_stream_once_while_the_other_arm_lags() -> None:
    """Two end events (two short trials) reach the session while one arm's samples lag: the
    leading arm applies the first end and waits for the stream to change; the second end belongs
    to the next stream, so no arm gets two end-of-stream batches in one stream."""
    from rcbht_introspection.live.segmenter import SegmenterSession, arm_stream_factory

    session = SegmenterSession(("L", "R"), arm_stream_factory())
    base = 1_700_000_000 * 10**9
    batches = []
    for i in range(10):
        for k, arm in enumerate(("L", "R")):
            out = session.push(arm, base + i * 5_000_000, [float(i)] * 6, source_ns=10 * i + k)
            batches += out.batches
    batches += session.phase("done", source_ns=95).batches
    batches += session.phase("done", source_ns=145).batches
    for i in range(10, 20):  # R lags: only L's samples arrive
        batches += session.push("L", base + i * 5_000_000, [float(i)] * 6, source_ns=10 * i).batches
    ends = [(b.arm, b.stream_id) for b in batches if b.end_of_stream]
    assert ends.count(("L", 0)) == 1, ends


def test_late_event_is_placed_at_the_sample_before_it() -> None:
    from rcbht_introspection.live.segmenter import SegmenterSession, arm_stream_factory

    session = SegmenterSession(("R",), arm_stream_factory())
    base = 1_700_000_000 * 10**9
    for i in range(10):
        session.push("R", base + i * 5_000_000, [float(i)] * 6, source_ns=100 * i)
    out = session.phase("rotation", source_ns=450)  # published after sample 4, arrives after 9
    assert [p.time for p in out.phases] == [0.02]  # placed at sample 4 all the same (counted)
    assert session.late_phases == 1


def test_session_rejects_malformed_samples() -> None:
    from rcbht_introspection.live.segmenter import SegmenterSession, arm_stream_factory

    session = SegmenterSession(("R",), arm_stream_factory(), subtasks=("approach",))
    base = 1_700_000_000 * 10**9
    assert session.push("R", base, [0.0] * 6).rejected is None
    assert session.push("R", base + 5_000_000, [float("nan")] + [0.0] * 5).rejected == "non_finite"
    assert session.push("R", 0, [0.0] * 6).rejected == "zero_stamp"
    assert session.push("R", base - 1, [0.0] * 6).rejected == "non_increasing_stamp"
    assert session.push("R", base, [0.0] * 6).rejected == "duplicate_sample"  # a re-sent one
    assert session.push("R", base + 10_000_000, [1.0] * 6).rejected is None
    counts = session.counts["R"]
    assert counts.accepted == 2 and counts.rejected_total == 4
    assert session.phase("pirouette").unknown_phase == "pirouette"


def test_end_event_waits_for_samples_still_in_flight() -> None:
    """The end event is flushed early only when no sample published before it is missing."""
    from rcbht_introspection.live.segmenter import SegmenterSession, arm_stream_factory

    ms = 1_000_000
    base = 1_700_000_000 * 10**9
    for last_sample, expect_early in ((99, True), (49, False)):
        session = SegmenterSession(("R",), arm_stream_factory(), hold_s=0.2, max_hold_s=10.0)
        for i in range(last_sample + 1):  # samples published every 1 ms
            session.push("R", base + i * 5 * ms, [float(i % 7)] * 6, source_ns=i * ms)
        done_at = 100 * ms  # published right after sample 99
        assert session.phase("done", source_ns=done_at).phases == []  # waits for a later sample
        early = session.flush(done_at + 300 * ms)
        assert bool(early.phases) is expect_early
        if not expect_early:  # samples 50..99 are missing: only the maximum hold applies it
            assert session.flush(done_at + 10_000 * ms).phases[0].name == "done"


def test_late_events_give_the_offline_words() -> None:
    """Events delivered after later-published samples still give the offline stream's words."""
    from rcbht_introspection.io.bags import END_PHASE, trial_phase_events
    from rcbht_introspection.live.offline import offline_stream_words

    trial, factory, session, ns = _session_with_stamps()
    events = [(t, name) for t, name in trial_phase_events(trial, END_PHASE) if name != END_PHASE]
    follows = _last_sample_before(events, ns)
    got: list[Word] = []
    for i in range(len(ns)):
        out = session.push("R", int(ns[i]), trial.wrench["R"][i], source_ns=10 * i)
        got += [w for b in out.batches for w in b.words]
        for (_, name), j in zip(events, follows, strict=True):
            if j + 5 == i:  # delivered five samples late
                got += [
                    w for b in session.phase(name, source_ns=10 * j + 5).batches for w in b.words
                ]
    out = session.phase(END_PHASE, source_ns=10 * len(ns))
    got += [w for b in [*out.batches, *session.flush(10**12).batches] for w in b.words]
    offline = offline_stream_words(trial, factory, END_PHASE)["R"]
    assert session.late_phases == len(events)
    assert got == offline and [w.seq for w in got] == [w.seq for w in offline]

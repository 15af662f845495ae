"""The pure parts of node health: /diagnostics statuses from counters, word-loss accounting."""

from __future__ import annotations

import math
from random import Random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rcbht_introspection.live.belief import UNKNOWN, BeliefTracker
from rcbht_introspection.live.health import (
    ERROR,
    OK,
    WARN,
    ArmHealth,
    CounterWatch,
    LatencyWindow,
    ModelStatus,
    classifier_health,
)
from rcbht_introspection.live.join import (
    MAX_BATCH_MESSAGES,
    LatchedEvents,
    Watermarks,
    WordLedger,
    batch_messages,
)
from rcbht_introspection.taxonomy.words import Level, Word


def test_an_arm_warns_in_the_period_a_loss_counter_moves_then_is_ok_again() -> None:
    arm = ArmHealth("R")
    arm.words(0, [Word("Fz", Level.PRIMITIVE, "cons", 0.0, 0.8, arm="R", seq=1)])
    first = arm.report(1.0, 1000, {"non_finite": 0}, {"gaps": 0}, 1.0, True)
    assert first.level == OK and first.message == "arm R: 1000 samples/s"
    values = dict(first.values)
    assert values["input rate (Hz)"] == "1000.0"
    assert math.isclose(float(values["finality backlog primitive (s)"]), 0.2)
    assert values["finality backlog behavior (s)"] == "nan"  # nothing released on that level yet
    moved = arm.report(1.0, 1500, {"non_finite": 2}, {"gaps": 1}, 1.5, True)
    assert moved.level == WARN
    assert moved.message == "arm R: 1 gaps, 2 rejected non_finite in the last period"
    assert dict(moved.values)["input rate (Hz)"] == "500.0"
    calm = arm.report(1.0, 1500, {"non_finite": 2}, {"gaps": 1}, 1.5, True)
    assert calm.level == OK and calm.message == "arm R: waiting for wrench"


def test_a_new_stream_restarts_the_finality_backlog() -> None:
    arm = ArmHealth("R")
    arm.words(0, [Word("Fz", Level.PRIMITIVE, "cons", 0.0, 30.0, arm="R", seq=1)])
    arm.words(1, [Word("Fz", Level.PRIMITIVE, "cons", 0.0, 0.5, arm="R", seq=1)])
    status = arm.report(1.0, 10, {}, {}, 1.0, True)
    assert math.isclose(float(dict(status.values)["finality backlog primitive (s)"]), 0.5)


def test_classifier_health_levels() -> None:
    latency = LatencyWindow()
    for ms in (1.0, 2.0, 3.0):
        latency.add(ms)
    usable = ModelStatus("m.rcbht", "ab", "", None)
    counts = {"words lost": 0}
    ok = classifier_health("active", usable, latency, counts, CounterWatch())
    assert ok.level == OK and dict(ok.values)["belief update latency p50 (ms)"] == "2.000"
    assert dict(ok.values)["belief updates in period"] == "3"
    assert latency.take()[0] == 0  # the period was taken
    missing = usable._replace(problem="no such file")
    bad = classifier_health("active", missing, latency, counts, CounterWatch())
    assert bad.level == ERROR and "no such file" in bad.message
    watch = CounterWatch()
    watch.moved({"words lost": 0})
    lost = classifier_health("active", usable, latency, {"words lost": 7}, watch)
    assert lost.level == WARN and lost.message == "7 words lost in the last period"


class _Model:
    """Always 'approach' (the tracker only needs classes_ and the two predict calls)."""

    classes_ = ("approach", "rotation")

    def predict_proba_samples(self, samples: list) -> list:
        return [[0.9, 0.1] for _ in samples]

    def predict_samples(self, samples: list) -> list:
        return ["approach" for _ in samples]


def _words(seqs: range, t0: float, level: Level = Level.PRIMITIVE) -> list[Word]:
    """One Fz word per number, a second each from t0."""
    return [
        Word("Fz", level, "cons", t0 + k, t0 + k + 1, arm="R", seq=s) for k, s in enumerate(seqs)
    ]


def test_a_word_is_lost_only_once_every_level_delivered_a_later_one() -> None:
    ledger = WordLedger()
    ledger.add(_words(range(1, 3), 0.0), now=2.0)
    ledger.add(_words(range(5, 6), 2.0), now=3.0)  # 3 and 4 may be in flight on other levels
    assert ledger.settle() == 0 and ledger.has_gap
    ledger.add(_words(range(3, 4), 0.0, Level.COMPOSITION), now=2.5)
    ledger.add(_words(range(6, 7), 0.0, Level.BEHAVIOR), now=4.0)
    assert ledger.settle() == 0 and ledger.has_gap  # the composition level has not passed 4
    ledger.add(_words(range(7, 8), 0.0, Level.COMPOSITION), now=5.0)
    assert ledger.settle() == 1  # 4 never came; words up to 5 may have reached time 3.0
    assert ledger.blind_until == 3.0 and ledger.lost == 1 and not ledger.has_gap
    ledger.end()
    assert ledger.settle() == 0 and ledger.settled == 7


def test_seq_end_proves_a_loss_as_soon_as_every_level_topic_passed_it() -> None:
    """Words.seq_end (or an empty watermark message) moves a level on without a word of its own."""
    ledger = WordLedger()
    ledger.add(_words(range(5, 7), 2.0), now=3.0, level=Level.PRIMITIVE, seq_end=6)
    assert ledger.settle() == 0 and ledger.has_gap  # 1..4 may be compositions in flight
    ledger.add([], now=3.1, level=Level.COMPOSITION, seq_end=6)
    ledger.add([], now=3.1, level=Level.BEHAVIOR, seq_end=6)
    assert ledger.settle() == 4 and ledger.blind_until == 3.0 and not ledger.has_gap


def test_watermarks_mark_idle_levels_of_the_running_stream_only() -> None:
    marks = Watermarks(idle_s=0.1)
    top = marks.batch("R", 0, _words(range(1, 4), 0.0))
    assert top == 3
    marks.published("R", 0, Level.PRIMITIVE, top, now=1.0)
    assert marks.due(1.05) == [
        ("R", 0, Level.COMPOSITION, 3),
        ("R", 0, Level.BEHAVIOR, 3),
    ]  # never published: due at once
    for level in (Level.COMPOSITION, Level.BEHAVIOR):
        marks.published("R", 0, level, 3, now=1.05)
    assert marks.due(1.1) == []  # nothing new
    marks.batch("R", 0, _words(range(4, 6), 1.0))
    marks.published("R", 0, Level.PRIMITIVE, 5, now=1.2)
    assert marks.due(1.12) == []  # idle for less than 0.1 s
    assert [d[2] for d in marks.due(1.2)] == [Level.COMPOSITION, Level.BEHAVIOR]
    marks.ended("R", 0)
    assert marks.due(5.0) == []
    assert marks.batch("R", 1, _words(range(1, 2), 0.0)) == 1  # a new stream numbers from 1


def test_a_late_join_blinds_the_sub_task_under_way_and_holds_its_verdict() -> None:
    tracker = BeliefTracker(_Model())
    tracker.phase("approach", 0.0)
    # joined late: words 1..9 were published before this classifier matched
    tracker.add_words("R", _words(range(10, 12), 3.0), now=5.0)
    assert tracker.account_losses() == 0  # not proven while other levels may still deliver
    tracker.phase("rotation", 6.0)
    assert tracker.take_finals() == []  # the approach verdict waits for the proof
    tracker.add_words("R", _words(range(12, 14), 6.0, Level.COMPOSITION), now=7.0)
    tracker.add_words("R", _words(range(14, 15), 6.0, Level.BEHAVIOR), now=8.0)
    assert tracker.account_losses() == 9
    assert tracker.account_losses() == 0  # counted once
    tracker.add_words("R", _words(range(15, 18), 6.0), now=9.0)
    tracker.phase("done", 9.0)
    tracker.end_of_stream("R")
    tracker.account_losses()
    finals = tracker.take_finals()
    assert [(b.phase, b.subtask, b.blind) for b in finals] == [
        ("approach", UNKNOWN, True),
        ("rotation", "approach", False),
    ]
    tracker.reset()  # a new stream starts with a clean slate
    tracker.add_words("R", _words(range(1, 3), 0.0), now=2.0)
    assert tracker.account_losses() == 0 and not tracker.current().blind


def test_latched_events_of_earlier_streams_are_dropped_and_the_running_ones_kept() -> None:
    history: LatchedEvents[str] = LatchedEvents(since_ns=1000)
    # replayed at the join, oldest first: two finished trials, then the running one
    for stream, name in [("s1", "approach"), ("s1", "done"), ("s2", "approach"), ("s2", "done")]:
        assert history.event(stream, name, published_ns=500, current=None) == []
    assert history.event("s3", "approach", published_ns=900, current=None) == []
    assert history.stream_started("s3") == ["approach"]  # the first live message of s3
    assert history.stale == 4
    assert history.event("s3", "rotation", published_ns=950, current="s3") == ["rotation"]
    assert history.event("s2", "done", published_ns=600, current="s3") == []
    assert history.stale == 5
    # live events always apply, whatever their stream
    assert history.event("s4", "approach", published_ns=2000, current="s3") == ["approach"]
    # re-activated: the latched topic replays what was applied already
    history.rejoin(since_ns=3000)
    assert history.event("s4", "approach", published_ns=2000, current="s4") == []


def test_a_stream_numbers_its_words_without_gaps() -> None:
    """The loss accounting rests on it: every word an arm releases, numbered 1, 2, 3, ..."""
    from rcbht_introspection.bench.ros import synthetic_trial
    from rcbht_introspection.taxonomy.stream import ArmStream

    trial = synthetic_trial("numbering", 20.0, seed=3)
    stream = ArmStream(arm="R")
    words = []
    for t, row in zip(trial.time, trial.wrench["R"], strict=True):
        words += stream.push(float(t), tuple(row))
    words += stream.finish()
    assert len(words) > 100
    assert sorted(w.seq for w in words) == list(range(1, len(words) + 1))


@pytest.mark.leases_domains  # takes every free domain for a moment
def test_ros_domains_leased_by_one_process_are_not_given_to_another() -> None:
    """Concurrent tests, replays and benchmarks each get a DDS domain of their own."""
    import json
    import subprocess
    import sys

    from rcbht_introspection.replay.supervision import DOMAIN_IDS, lease_domain, release_domain

    mine = {lease_domain() for _ in range(5)}
    assert len(mine) == 5 and mine <= set(DOMAIN_IDS)
    child = (
        "import json\n"
        "from rcbht_introspection.errors import InputError\n"
        "from rcbht_introspection.replay.supervision import lease_domain\n"
        "got = []\n"
        "try:\n"
        "    while True: got.append(lease_domain())\n"
        "except InputError: print(json.dumps(got))\n"
    )
    try:
        out = subprocess.run(
            [sys.executable, "-c", child], capture_output=True, text=True, check=True
        )
        theirs = set(json.loads(out.stdout))
        assert theirs and not theirs & mine
    finally:
        release_domain()
    out = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True, check=True)
    assert mine <= set(json.loads(out.stdout))  # released: free for others again


def _numbered(levels: list[Level]) -> list[Word]:
    """Words numbered 1, 2, ... in release order, one per entry of `levels`."""
    return [Word("Fz", lv, "cons", k, k + 1, arm="R", seq=k + 1) for k, lv in enumerate(levels)]


@given(
    levels=st.lists(st.sampled_from(list(Level)), max_size=200),
    max_words=st.integers(1, 40),
    end=st.booleans(),
    order=st.randoms(use_true_random=False),
)
@settings(max_examples=200, deadline=None)
def test_batch_pieces_never_prove_a_word_of_a_later_piece_lost(
    levels: list[Level], max_words: int, end: bool, order: Random
) -> None:
    """Level topics deliver their pieces in order but interleave freely; settling after every
    message must count no loss, and every word arrives once, with one end per level at the end."""
    words = _numbered(levels)
    messages = batch_messages(words, len(words), end, max_words)
    assert all(len(m.words) <= max_words for m in messages)
    assert len(messages) <= MAX_BATCH_MESSAGES
    queues = {lv: [m for m in messages if m.level == lv] for lv in Level}
    ledger = WordLedger()
    received: list[Word] = []
    while any(queues.values()):
        level = order.choice([lv for lv, q in queues.items() if q])
        message = queues[level].pop(0)
        received += message.words
        ledger.add(message.words, 0.0, message.level, message.seq_end)
        if message.end_of_stream:
            ledger.end(message.level)
        assert ledger.settle() == 0
    assert sorted(w.seq for w in received) == list(range(1, len(words) + 1))
    ends = [m.level for m in messages if m.end_of_stream]
    assert ends == (list(Level) if end else [])


def test_a_missing_piece_is_proven_lost() -> None:
    words = _numbered([Level.PRIMITIVE] * 70 + [Level.COMPOSITION])
    messages = batch_messages(words, 71, max_words=32)
    assert [len(m.words) for m in messages] == [32, 32, 6, 1]
    ledger = WordLedger()
    for m in (messages[0], messages[2], messages[3]):  # the second primitive piece never came
        ledger.add(m.words, 0.0, m.level, m.seq_end)
    ledger.add([], 0.0, Level.BEHAVIOR, 71)  # the behaviour level's watermark
    assert ledger.settle() == 32


def test_a_huge_batch_keeps_within_the_uint8_batch_size() -> None:
    words = _numbered([Level.PRIMITIVE] * 20000)
    messages = batch_messages(words, 20000, max_words=32)
    assert len(messages) <= MAX_BATCH_MESSAGES
    assert sum(len(m.words) for m in messages) == 20000

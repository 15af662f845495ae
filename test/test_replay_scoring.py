"""replay/scoring.py without ROS: hand-made records of a tiny trial, scored as `rcbht replay-eval` does."""

from __future__ import annotations

import json
from collections.abc import Collection, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from rcbht_introspection.io.bags import END_PHASE, WRENCH_TYPE, BagMessage, encode_wrench
from rcbht_introspection.io.trial import SUBTASKS, Trial
from rcbht_introspection.live.belief import Belief
from rcbht_introspection.replay.scoring import (
    AppliedPhase,
    BagRecord,
    Observations,
    Playback,
    ReceivedBelief,
    Reference,
    bag_record,
    score,
    state_timeline,
)
from rcbht_introspection.taxonomy.words import Level, Word

ORIGIN = 1_700_000_000 * 10**9
WALL0 = 10**12
"""Wall clock (ns) at which the first sample of a bag was published (small: exact as a float)."""
MS = 1_000_000


def tiny_trial(name: str = "tiny") -> Trial:
    """4 s at 10 Hz, one arm, the four sub-tasks starting at 0, 1, 2 and 3 s."""
    t = np.round(np.arange(0.0, 4.01, 0.1), 6)
    return Trial(name, t, {"R": np.zeros((len(t), 6))}, state_times=(0.0, 1.0, 2.0, 3.0))


def belief(subtask: str, final: bool = False) -> Belief:
    return Belief(subtask, tuple(SUBTASKS), (0.7, 0.1, 0.1, 0.1), 0.0, 1.0, "boundary", final=final)


def stamp(t: float) -> int:
    return ORIGIN + round(t * 1e9)


def playback(trial: Trial, published: int | None = None) -> Playback:
    """Every sample published at wall WALL0 + its stream time (real-time playback)."""
    stamps = [stamp(float(t)) for t in trial.time]
    series = [(WALL0 + s - ORIGIN, s) for s in stamps]
    return Playback(
        Path("tiny.mcap"),
        origin=stamps[0],
        published=len(stamps) if published is None else published,
        play_s=4.0,
        pub_wall={s: w for w, s in series},
        pub_series=series,
    )


def record(
    trial: Trial,
    verdicts: list[str],
    beliefs: Sequence[ReceivedBelief] = (),
    states: Sequence[tuple[int, str]] = (),
    accepted: int | None = None,
    rejected: int = 0,
    initial_state: str = "unknown",
    word_arrivals: Sequence[tuple[int, int]] = (),
    triggers: Collection[int] = (),
    event_stamps: Collection[int] = (),
) -> BagRecord:
    """A bag's record: `beliefs`, then final beliefs with `verdicts`; counters at its end."""
    finals = [ReceivedBelief(WALL0, belief(v, final=True), 0, WALL0) for v in verdicts]
    pb = playback(trial)
    ends = {("R", "primitives"): (pb.published if accepted is None else accepted, rejected)}
    return BagRecord(
        playback=pb,
        initial_state=initial_state,
        beliefs=[*beliefs, *finals],
        word_arrivals=list(word_arrivals),
        states=list(states),
        words={("R", level): [] for level in ("primitives", "compositions", "behaviors")},
        ends=ends,
        triggers=set(triggers),
        event_stamps=set(event_stamps),
    )


def test_correct_and_incorrect_verdicts_count_against_the_truth() -> None:
    trial = tiny_trial()
    rec = record(trial, ["approach", "rotation", "mating", "mating"])
    result = score([rec], [trial], ("R",), "boundary")
    assert result["subtasks"] == 4 and result["subtasks_correct"] == 3
    assert result["subtask_accuracy"] == 0.75
    bag = result["per_bag"][0]
    assert bag["truth"] == list(SUBTASKS)
    assert bag["verdicts"] == ["approach", "rotation", "mating", "mating"]
    assert bag["truth_starts"] == [0.0, 1.0, 2.0, 3.0] and bag["duration"] == 4.0
    assert bag["final_probabilities"][0] == dict(zip(SUBTASKS, (0.7, 0.1, 0.1, 0.1), strict=True))
    json.dumps(result)  # what `rcbht replay-eval --json` writes


def test_a_missing_verdict_is_a_wrong_one_and_no_later_verdict_moves_up() -> None:
    trial = tiny_trial()
    result = score([record(trial, ["approach", "insertion"])], [trial], ("R",), "boundary")
    # the second verdict is compared with the second sub-task (rotation), not with insertion
    assert (result["subtasks"], result["subtasks_correct"]) == (4, 1)
    assert result["subtask_accuracy"] == 0.25


def test_without_a_reference_or_in_window_mode_the_offline_figures_are_none() -> None:
    trial = tiny_trial()
    rec = record(trial, [])
    boundary = score([rec], [trial], ("R",), "boundary")
    assert boundary["verdicts_match_offline"] is None and boundary["words_match_offline"] is None
    assert "offline_verdicts" not in boundary["per_bag"][0]
    assert boundary["subtask_accuracy"] == 0.0
    window = score([rec], [trial], ("R",), "window")
    assert window["subtask_accuracy"] is None and window["subtasks"] == 4


def test_latency_percentiles_per_kind_of_trigger() -> None:
    """Sample-triggered beliefs and words give latencies; events' and finals' are apart or none."""
    trial = tiny_trial()
    pb = playback(trial)
    s = [stamp(t) for t in (0.5, 1.0, 1.5, 2.0)]
    wall = {x: pb.pub_wall[x] for x in s}
    beliefs = [
        ReceivedBelief(wall[s[0]] + 3 * MS, belief("approach"), s[0], wall[s[0]] + 1 * MS),
        ReceivedBelief(wall[s[2]] + 4 * MS, belief("approach"), s[2], wall[s[2]] + 2 * MS),
        ReceivedBelief(wall[s[3]] + 9 * MS, belief("rotation"), s[3], wall[s[3]] + 3 * MS),
        # words finalised by the event applied at s[1]: an event latency, not a sample's
        ReceivedBelief(wall[s[1]] + 9 * MS, belief("rotation"), s[1], wall[s[1]] + 7 * MS),
        # a trigger that finalised no words (not in `triggers`) and a final belief: none
        ReceivedBelief(WALL0 + 50 * MS, belief("rotation"), stamp(3.0), WALL0 + 50 * MS),
        ReceivedBelief(wall[s[0]] + 80 * MS, belief("approach", final=True), s[0], WALL0),
    ]
    rec = record(
        trial,
        [],
        beliefs=beliefs,
        triggers=set(s),
        event_stamps={s[1]},
        word_arrivals=[(wall[s[0]] + 1 * MS, s[0]), (wall[s[1]] + 5 * MS, s[1])],
    )
    result = score([rec], [trial], ("R",), "boundary")
    assert result["latency_ms"] == {"p50": 2.0, "p99": 2.98, "max": 3.0, "n": 3}
    assert result["latency_received_ms"] == {"p50": 4.0, "p99": 8.9, "max": 9.0, "n": 3}
    assert result["event_latency_ms"] == {"p50": 7.0, "p99": 7.0, "max": 7.0, "n": 1}
    assert result["word_latency_ms"] == {"p50": 1.0, "p99": 1.0, "max": 1.0, "n": 1}
    empty = score([record(trial, [])], [trial], ("R",), "boundary")
    assert empty["latency_ms"] == {"p50": None, "p99": None, "max": None, "n": 0}


def test_drops_come_from_the_segmenters_cumulative_counters() -> None:
    trial = tiny_trial()
    n = len(trial.time)
    first = record(trial, [], accepted=n - 2, rejected=1)
    # the second bag's counters include the first bag's samples
    second = record(trial, [], accepted=2 * n - 2, rejected=1)
    result = score([first, second], [trial, trial], ("R",), "boundary")
    assert [b["dropped_wrench"] for b in result["per_bag"]] == [2, 0]
    assert result["dropped_wrench"] == 2 and result["rejected_wrench"] == 1
    # no end of stream at all: everything published counts as dropped
    lost = replace(record(trial, []), ends={})
    assert score([lost], [trial], ("R",), "boundary")["dropped_wrench"] == n


def test_task_state_timeline_on_the_stream_clock_and_its_accuracy() -> None:
    trial = tiny_trial()
    states = [
        (WALL0 + round(t * 1e9), s) for t, s in zip((1.0, 2.0, 3.0), SUBTASKS[1:], strict=True)
    ]
    rec = record(trial, [], states=states, initial_state="approach")
    assert state_timeline(rec) == [(1.0, "rotation"), (2.0, "insertion"), (3.0, "mating")]
    assert state_timeline(replace(rec, playback=Playback(Path("none.mcap")))) == []
    result = score([rec], [trial], ("R",), "boundary")
    assert result["time_accuracy"] == 1.0 and result["state_changes"] == 3
    late = record(trial, [], states=[(s[0] + 500 * MS, s[1]) for s in states])
    bag = score([late], [trial], ("R",), "boundary")["per_bag"][0]
    # unknown for the first second, then each state half a second late: 1.5 s of 4 right
    assert bag["time_accuracy"] == pytest.approx(1.5 / 4, abs=1e-3)
    assert bag["timeline"] == [(1.5, "rotation"), (2.5, "insertion"), (3.5, "mating")]
    assert bag["initial_state"] == "unknown"


def test_playback_counts_wrench_and_keeps_the_first_wall_time_of_each_stamp() -> None:
    pb = Playback(Path("b.mcap"))
    raw = encode_wrench(stamp(0.0), "R", [0.0] * 6)
    pb.on_publish(BagMessage("/R/wrench", WRENCH_TYPE, 0, raw), WALL0)
    pb.on_publish(BagMessage("/L/wrench", WRENCH_TYPE, 0, raw), WALL0 + 7)  # same stamp
    pb.on_publish(BagMessage("/task_phase", "std_msgs/msg/String", 0, b""), WALL0 + 9)
    pb.on_publish(BagMessage("/R/wrench", WRENCH_TYPE, 1, encode_wrench(stamp(0.1), "R", [0.0] * 6)), WALL0 + 20)  # fmt: skip
    assert pb.origin == stamp(0.0) and pb.published == 3
    assert pb.pub_wall == {stamp(0.0): WALL0, stamp(0.1): WALL0 + 20}
    assert pb.pub_series == [(WALL0, stamp(0.0)), (WALL0 + 20, stamp(0.1))]


def test_a_bag_record_holds_only_its_stream_and_what_came_after_the_mark() -> None:
    obs = Observations()
    old_word = Word("Fz", Level.PRIMITIVE, "cons", 0.0, 1.0, arm="R")
    obs.states.append((1, "rotation"))
    obs.beliefs.append(ReceivedBelief(1, belief("rotation", final=True), 0, 1))
    obs.word_arrivals.append((1, 10))
    obs.words[(0, "R", "primitives")] = [old_word]
    obs.ends[(0, "R", "primitives")] = (5, 0)
    since = obs.mark()
    assert since.initial_state == "rotation" and since.beliefs == 1
    new_word = Word("Fz", Level.PRIMITIVE, "bpos", 0.0, 0.5, arm="R")
    obs.states.append((2, "approach"))
    obs.beliefs.append(ReceivedBelief(2, belief("approach", final=True), 20, 2))
    obs.word_arrivals.append((2, 20))
    obs.words[(1, "R", "primitives")] = [new_word]
    obs.triggers[1] = {20}
    obs.phases.append(AppliedPhase(2, "approach", 0.0, 1, 20))
    obs.phases.append(AppliedPhase(1, "done", 1.0, 0, 10))
    assert not obs.ended(1, ("R",))
    for level in ("primitives", "compositions", "behaviors"):
        obs.ends[(1, "R", level)] = (12, 0)
    assert obs.ended(1, ("R",)) and len(obs.finals_since(since.beliefs)) == 1
    rec = bag_record(obs, since, 1, ("R",), Playback(Path("b.mcap")))
    assert rec.initial_state == "rotation" and rec.states == [(2, "approach")]
    assert [b.belief.subtask for b in rec.beliefs] == ["approach"]
    assert rec.word_arrivals == [(2, 20)] and rec.triggers == {20} and rec.event_stamps == {20}
    assert rec.words[("R", "primitives")] == [new_word] and rec.words[("R", "behaviors")] == []
    assert rec.ends[("R", "primitives")] == (12, 0) and len(rec.ends) == 3


def test_words_and_verdicts_against_the_offline_run(tmp_path: Path) -> None:
    """The offline reference: the same words match; one word missing is named."""
    from rcbht_introspection.bench.stops import toy_model
    from rcbht_introspection.learn.model_file import load_model
    from rcbht_introspection.live import offline
    from rcbht_introspection.live.segmenter import arm_stream_factory

    t = np.round(np.arange(0.0, 4.0, 0.005), 6)
    force = np.column_stack([np.zeros((len(t), 2)), 10 * np.sin(t * 3), np.zeros((len(t), 3))])
    trial = Trial("wave", t, {"R": force}, state_times=(0.0, 1.0, 2.0, 3.0))
    ref = Reference(load_model(toy_model(tmp_path / "m.rcbht")), arm_stream_factory())
    words = offline.offline_stream_words(trial, ref.stream_factory, END_PHASE)["R"]
    verdicts = offline.offline_verdicts(ref.model, trial, {"R": words})
    assert len(verdicts) == 4 and words

    def with_words(seq: list[Word]) -> BagRecord:
        rec = record(trial, verdicts)
        by_level = {
            ("R", lv.value + "s"): [w for w in seq if w.level == lv]
            for lv in (Level.PRIMITIVE, Level.COMPOSITION, Level.BEHAVIOR)
        }
        return replace(rec, words=by_level)

    same = score([with_words(words)], [trial], ("R",), "boundary", ref)
    assert same["words_match_offline"] is True and same["verdicts_match_offline"] is True
    bag = same["per_bag"][0]
    assert bag["offline_verdicts"] == verdicts and bag["words_mismatch"] == ""
    assert bag["node_words"] == bag["offline_words"] == len(words)
    first_primitive = next(i for i, w in enumerate(words) if w.level == Level.PRIMITIVE)
    fewer = words[:first_primitive] + words[first_primitive + 1 :]
    short = score([with_words(fewer)], [trial], ("R",), "boundary", ref)
    assert short["words_match_offline"] is False
    assert short["per_bag"][0]["words_mismatch"].startswith("arm R primitive: ")


def test_task_state_and_beliefs_against_the_nodes_sessions_run_offline(tmp_path: Path) -> None:
    """Two bags in turn: what the offline run of the nodes' own sessions publishes matches;
    a state change that differs, or a belief too few, is named per bag."""
    from rcbht_introspection.bench.stops import toy_model
    from rcbht_introspection.learn.model_file import load_model
    from rcbht_introspection.live.replay import node_stream, replay_beliefs
    from rcbht_introspection.live.segmenter import arm_stream_factory
    from rcbht_introspection.live.state import TaskStateConfig

    t = np.round(np.arange(0.0, 4.0, 0.005), 6)
    force = np.column_stack([np.zeros((len(t), 2)), 10 * np.sin(t * 3), np.zeros((len(t), 3))])
    trials = [Trial(f"wave{k}", t, {"R": force}, state_times=(0.0, 1.0, 2.0, 3.0)) for k in (1, 2)]
    loose = TaskStateConfig(min_probability=0.0, min_words=0)  # the toy model is never sure
    ref = Reference(load_model(toy_model(tmp_path / "m.rcbht")), arm_stream_factory(), loose)
    streamed = node_stream(trials, ref.stream_factory)
    runs = replay_beliefs(streamed, ref.model, trials=trials, state_config=loose)
    assert any(r.changes for r in runs)

    def as_received(k: int, changed: str = "", drop: int = 0) -> BagRecord:
        run = runs[k]
        beliefs = [ReceivedBelief(WALL0, b, 0, WALL0) for b in run.beliefs][drop:]
        states = [(WALL0 + i, changed or s) for i, (_, s) in enumerate(run.changes)]
        return replace(
            record(trials[k], []), beliefs=beliefs, states=states, initial_state=run.initial
        )

    same = score([as_received(0), as_received(1)], trials, ("R",), "boundary", ref)
    assert same["states_match_offline"] is True and same["beliefs_match_offline"] is True
    assert same["offline_state_changes"] == sum(len(r.changes) for r in runs)
    assert same["per_bag"][1]["offline_timeline"] == [(round(x, 3), s) for x, s in runs[1].changes]
    k = next(i for i, r in enumerate(runs) if r.changes)
    bags = [as_received(0), as_received(1)]
    bags[k] = as_received(k, changed="mating" if runs[k].changes[0][1] != "mating" else "rotation")
    other = score(bags, trials, ("R",), "boundary", ref)
    assert other["states_match_offline"] is False and other["beliefs_match_offline"] is True
    assert [b["states_match_offline"] for b in other["per_bag"]] == [k != 0, k != 1]
    fewer = score([as_received(0, drop=1), as_received(1)], trials, ("R",), "boundary", ref)
    assert fewer["beliefs_match_offline"] is False and fewer["states_match_offline"] is True


@pytest.mark.parametrize("option", ["--teach-beside", "--teach-restart"])
def test_teaching_options_need_teach_first(option: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Refused in one line before any node starts."""
    from rcbht_introspection.cli import main

    assert main(["replay-eval", "bag.mcap", "--model", "m.rcbht", option]) == 2
    err = capsys.readouterr().err.strip()
    assert "need --teach-first" in err and "\n" not in err

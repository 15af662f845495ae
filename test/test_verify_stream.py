"""The verifier node's state without ROS (verify/stream.py): a held-out trial's bag messages fed
in playback order give the offline verifier's verdicts, stream after stream."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from verify_support import simulated_verifier

from rcbht_introspection.io.bags import (
    PHASE_TOPIC,
    WRENCH_TYPE,
    arm_of_topic,
    bag_messages,
    decode_string,
    decode_wrench,
    write_trial_bag,
)
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.verify.model_file import VerifierModel, load_verifier
from rcbht_introspection.verify.monitor import NOMINAL
from rcbht_introspection.verify.stream import StreamVerdict, VerifierStream, offline_verdicts


@pytest.fixture(scope="module")
def verifier(tmp_path_factory: pytest.TempPathFactory) -> tuple[VerifierModel, list[Trial]]:
    path, held_out = simulated_verifier(tmp_path_factory.mktemp("verifier"))
    return load_verifier(path), held_out


def play(stream: VerifierStream, bag: Path, health: list[str]) -> list[StreamVerdict]:
    """The bag's wrench samples and events into `stream`, in playback order."""
    out = []
    for m in bag_messages(bag):
        if m.msgtype == WRENCH_TYPE:
            stamp, frame, values = decode_wrench(m.raw)
            got = stream.push(arm_of_topic(m.topic, frame), stamp, values)
        elif m.topic == PHASE_TOPIC:
            got = stream.phase(decode_string(m.raw))
        else:
            continue
        out += got.verdicts
        if not health or health[-1] != stream.health:
            health.append(stream.health)
    return out


def test_streams_give_the_offline_verdicts(
    verifier: tuple[VerifierModel, list[Trial]], tmp_path: Path
) -> None:
    model, held_out = verifier
    stream = VerifierStream(model, model.arms)
    for stream_id, trial in enumerate(held_out):
        bag = tmp_path / f"{trial.name}.mcap"
        write_trial_bag(trial, bag)
        health: list[str] = []
        got = play(stream, bag, health)
        offline = offline_verdicts(trial, model)
        assert [sv.verdict for sv in got] == offline
        assert {sv.stream_id for sv in got} == {stream_id}
        first = got[0]
        assert first.stamp_ns == first.origin_ns + round(first.verdict.time * 1e9)
        for sv in got:
            v = sv.verdict
            if v.alarm:
                assert sv.evidence_start == v.onset
            else:
                starts = [t for t in trial.state_times if t - trial.time[0] <= v.time]
                assert math.isclose(
                    sv.evidence_start, (starts[-1] - trial.time[0]) if starts else 0.0
                )
        # nothing is published as failure before the threshold: health follows the alarm
        alarm = offline[-1].alarm_time
        assert health[-1] == offline[-1].health
        assert all(
            sv.verdict.health == NOMINAL for sv in got if alarm is None or sv.verdict.time < alarm
        )
        assert all(
            sv.verdict.score <= 1.0 for sv in got if alarm is None or sv.verdict.time < alarm
        )
    assert stream.segmenter.stream_id == len(held_out)


def test_arms_must_be_the_models(verifier: tuple[VerifierModel, list[Trial]]) -> None:
    model, _ = verifier
    with pytest.raises(ValueError, match="differ from the verifier model"):
        VerifierStream(model, ("L", "R"))


def test_a_contradicting_final_belief_raises_the_alarm_from_the_latest_sample(
    verifier: tuple[VerifierModel, list[Trial]], tmp_path: Path
) -> None:
    """What verifier_node does with rcbht/belief: a final verdict that contradicts its sub-task
    counts from the stream's latest sample on (the offline verifier given the same contradiction
    at that time agrees); a running belief, or one that agrees, changes nothing."""
    from rcbht_introspection.live.belief import Belief
    from rcbht_introspection.verify.mismatch import MISMATCH

    model, held_out = verifier

    def quiet_until_the_middle(t: Trial) -> bool:
        alarm = offline_verdicts(t, model)[-1].alarm_time
        return alarm is None or alarm > float(t.time[-1] - t.time[0]) / 2 + 1.0

    quiet = [t for t in held_out if quiet_until_the_middle(t)]
    assert quiet, "no held-out trial without an alarm in its first half to test on"
    trial = quiet[0]
    bag = tmp_path / f"{trial.name}.mcap"
    write_trial_bag(trial, bag)
    messages = [m for m in bag_messages(bag) if m.msgtype == WRENCH_TYPE or m.topic == PHASE_TOPIC]
    stream = VerifierStream(model, model.arms)
    got: list[StreamVerdict] = []
    start = float(trial.state_times[1] - trial.time[0])
    phase = trial.phase_names[1]
    other = next(n for n in trial.phase_names if n != phase)
    contradiction = None
    for i, m in enumerate(messages):
        if m.msgtype == WRENCH_TYPE:
            stamp, frame, values = decode_wrench(m.raw)
            got += stream.push(arm_of_topic(m.topic, frame), stamp, values).verdicts
        else:
            got += stream.phase(decode_string(m.raw)).verdicts
        if i == len(messages) // 2:

            def belief(name: str, final: bool) -> Belief:
                classes, p = (name, phase), (0.9, 0.1)
                return Belief(name, classes, p, start, start + 1, "boundary", phase, final)

            assert stream.belief(belief(other, final=False)) is None  # running: not a verdict
            assert stream.belief(belief(phase, final=True)) is None  # agrees
            stale = Belief(other, (other, phase), (0.9, 0.1), start + 0.5, start + 1, "boundary", phase, True)  # fmt: skip
            assert stream.belief(stale) is None  # not a sub-task of this stream (an older one's)
            contradiction = stream.belief(belief(other, final=True))
    assert contradiction is not None and contradiction.start == start
    verdicts = [sv.verdict for sv in got]
    assert verdicts == offline_verdicts(trial, model, [contradiction])
    alarm = verdicts[-1].alarm_time
    assert alarm is not None and alarm >= contradiction.time - 1e-9
    assert verdicts[-1].onset == start and verdicts[-1].signals[MISMATCH] > 1
    assert all(not v.alarm for v in verdicts if v.time < contradiction.time - 1e-9)

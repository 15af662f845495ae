"""The rcbht_interfaces (and ROS) messages <-> the core records: Word, Belief, verdicts, health; for the nodes and the ROS tools."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from diagnostic_msgs.srv import SelfTest
from geometry_msgs.msg import WrenchStamped
from rcbht_interfaces.msg import Belief as BeliefMsg
from rcbht_interfaces.msg import Phase as PhaseMsg
from rcbht_interfaces.msg import TeachRequest as TeachRequestMsg
from rcbht_interfaces.msg import Verdict as VerdictMsg
from rcbht_interfaces.msg import Word as WordMsg
from rcbht_interfaces.msg import Words as WordsMsg
from rcbht_interfaces.msg import WrenchBlock as WrenchBlockMsg
from rcbht_interfaces.srv import Teach

from rcbht_introspection.live.belief import Belief
from rcbht_introspection.live.classifier import PhaseInput, WordsInput
from rcbht_introspection.live.health import OK, WARN, Health
from rcbht_introspection.live.publication import WordsOut
from rcbht_introspection.live.segmenter import ArmCounts, PhaseEvent
from rcbht_introspection.live.teach import TeachRequest, TeachStatus
from rcbht_introspection.summaries.blocks import WrenchBlock
from rcbht_introspection.taxonomy.words import LEVELS, Level, Word

if TYPE_CHECKING:  # verdicts come from verifier_node's model: segmenter_node loads none
    from rcbht_introspection.verify.stream import StreamVerdict

LEVEL_CODES: dict[Level, int] = {level: i for i, level in enumerate(LEVELS)}
_NS = 1_000_000_000


def to_time(ns: int) -> Time:
    """Integer nanoseconds -> builtin_interfaces/Time."""
    ns = int(ns)
    return Time(sec=ns // _NS, nanosec=ns % _NS)


def to_ns(t: Time) -> int:
    """builtin_interfaces/Time -> integer nanoseconds."""
    return int(t.sec) * _NS + int(t.nanosec)


def wrench_sample(msg: WrenchStamped) -> tuple[int, tuple[float, ...]]:
    """(stamp ns, (Fx, Fy, Fz, Mx, My, Mz)) of a WrenchStamped."""
    f, m = msg.wrench.force, msg.wrench.torque
    return to_ns(msg.header.stamp), (f.x, f.y, f.z, m.x, m.y, m.z)


def word_to_msg(word: Word) -> WordMsg:
    """Word -> rcbht_interfaces/Word."""
    return WordMsg(
        arm=word.arm,
        axis=word.axis,
        level=LEVEL_CODES[word.level],
        label=word.label,
        start=float(word.start),
        end=float(word.end),
        seq=int(word.seq),
        sublabels=list(word.sublabels),
        feature_keys=list(word.features),
        feature_values=[float(v) for v in word.features.values()],
    )


def msg_to_word(msg: WordMsg) -> Word:
    """rcbht_interfaces/Word -> Word."""
    return Word(
        axis=msg.axis,
        level=LEVELS[msg.level],
        label=msg.label,
        start=msg.start,
        end=msg.end,
        features=dict(zip(msg.feature_keys, (float(v) for v in msg.feature_values), strict=True)),
        arm=msg.arm,
        seq=int(msg.seq),
        sublabels=tuple(msg.sublabels),
    )


def words_msg(
    arm: str,
    level: Level,
    words: Sequence[Word],
    stamp_ns: int,
    origin_ns: int,
    *,
    stream_id: int = 0,
    batch_size: int = 1,
    end_of_stream: bool = False,
    accepted: int = 0,
    rejected: int = 0,
    seq_end: int = 0,
    frame_id: str = "",
    wrench: Sequence[WrenchBlock] = (),
) -> WordsMsg:
    """A batch of words of one arm and level that became final at the sample `stamp_ns`."""
    msg = WordsMsg(
        arm=arm,
        level=LEVEL_CODES[level],
        time_origin=to_time(origin_ns),
        stream_id=int(stream_id),
        words=[word_to_msg(w) for w in words],
        batch_size=int(batch_size),
        end_of_stream=end_of_stream,
        samples_accepted=int(accepted),
        samples_rejected=int(rejected),
        seq_end=int(seq_end),
        wrench=[WrenchBlockMsg(end=b.end, samples=b.samples, mean=b.mean) for b in wrench],
    )
    msg.header.stamp = to_time(stamp_ns)
    msg.header.frame_id = frame_id
    return msg


def words_out_msg(item: WordsOut, counts: ArmCounts) -> WordsMsg:
    """One message of live/publication.py (a batch's level, or an idle watermark) as sent."""
    batch, message = item.batch, item.message
    return words_msg(
        batch.arm,
        message.level,
        message.words,
        batch.stamp_ns,
        batch.origin_ns,
        stream_id=batch.stream_id,
        batch_size=item.batch_size,
        end_of_stream=message.end_of_stream,
        accepted=counts.accepted,
        rejected=counts.rejected_total,
        seq_end=message.seq_end,
        wrench=item.wrench,
    )


def words_from_msg(msg: WordsMsg) -> tuple[list[Word], float]:
    """(words, stream time of the sample that finalised them)."""
    now = (to_ns(msg.header.stamp) - to_ns(msg.time_origin)) / 1e9
    return [msg_to_word(w) for w in msg.words], now


def words_input(arm: str, msg: WordsMsg) -> WordsInput:
    """A received Words message as the classifier session's input."""
    words, now = words_from_msg(msg)
    return WordsInput(
        arm=arm,
        level=LEVELS[msg.level],
        words=words,
        now=now,
        stamp_ns=to_ns(msg.header.stamp),
        stream=(to_ns(msg.time_origin), int(msg.stream_id)),
        batch_size=int(msg.batch_size),
        end_of_stream=bool(msg.end_of_stream),
        seq_end=int(msg.seq_end),
        wrench=tuple(
            WrenchBlock(float(b.end), int(b.samples), tuple(float(v) for v in b.mean))
            for b in msg.wrench
        ),
    )


def phase_input(msg: PhaseMsg, published_ns: int | None) -> PhaseInput:
    """A received Phase message as the classifier session's input."""
    return PhaseInput(
        name=msg.name,
        time=float(msg.time),
        stamp_ns=to_ns(msg.header.stamp),
        stream=(to_ns(msg.time_origin), int(msg.stream_id)),
        published_ns=published_ns,
    )


def phase_msg(event: PhaseEvent) -> PhaseMsg:
    """Applied sub-task event -> rcbht_interfaces/Phase."""
    msg = PhaseMsg(
        name=event.name,
        time=float(event.time),
        time_origin=to_time(event.origin_ns),
        stream_id=int(event.stream_id),
    )
    msg.header.stamp = to_time(event.stamp_ns)
    return msg


def belief_msg(belief: Belief, stamp_ns: int, trigger_ns: int = 0) -> BeliefMsg:
    """Belief -> rcbht_interfaces/Belief (stamp: when computed; trigger: the wrench sample behind it)."""
    msg = BeliefMsg(
        subtask=belief.subtask,
        classes=list(belief.classes),
        probabilities=[float(p) for p in belief.probabilities],
        window_start=float(belief.start),
        window_end=float(belief.end),
        mode=belief.mode,
        phase=belief.phase,
        final=belief.final,
        n_words=int(belief.n_words),
        trigger_stamp=to_time(trigger_ns),
    )
    msg.header.stamp = to_time(stamp_ns)
    return msg


def belief_from_msg(msg: BeliefMsg) -> Belief:
    """rcbht_interfaces/Belief -> Belief."""
    return Belief(
        subtask=msg.subtask,
        classes=tuple(msg.classes),
        probabilities=tuple(float(p) for p in msg.probabilities),
        start=msg.window_start,
        end=msg.window_end,
        mode=msg.mode,
        phase=msg.phase,
        final=msg.final,
        n_words=int(msg.n_words),
    )


def diagnostic_array(statuses: Sequence[Health], stamp: Time) -> DiagnosticArray:
    """Health records -> one diagnostic_msgs/DiagnosticArray (hardware_id: this host's node)."""
    msg = DiagnosticArray()
    msg.header.stamp = stamp
    msg.status = [
        DiagnosticStatus(
            level=bytes([h.level]),
            name=h.name,
            message=h.message,
            hardware_id="rcbht_introspection",
            values=[KeyValue(key=k, value=v) for k, v in h.values],
        )
        for h in statuses
    ]
    return msg


def self_test_status(response: SelfTest.Response, name: str, passed: bool, message: str) -> None:
    """Fill a diagnostic_msgs/SelfTest response (the ~/tare answer: taken or not, and why)."""
    response.id = name
    response.passed = bytes([passed])  # a `byte` field
    level = bytes([OK if passed else WARN])
    response.status = [DiagnosticStatus(level=level, name=name, message=message)]


def teach_response(response: Teach.Response, status: TeachStatus) -> Teach.Response:
    """Fill the ~/teach service's response from the session's answer."""
    response.accepted, response.message = status.accepted, status.message
    response.pending, response.taught_windows = status.pending, status.taught_windows
    response.model_version, response.errors = status.model_version, status.errors
    return response


def teach_request(msg: Teach.Request | TeachRequestMsg) -> TeachRequest:
    """A ~/teach request or a teach topic message as the session's TeachRequest."""
    return TeachRequest(msg.label, msg.last, msg.start, msg.end, msg.request_id)


def verdict_msg(sv: StreamVerdict, subtask: str) -> VerdictMsg:
    """StreamVerdict -> rcbht_interfaces/Verdict (signal scores raw, beside their thresholds)."""
    v = sv.verdict
    thresholds = list(v.thresholds.values())
    nan = math.nan
    msg = VerdictMsg(
        time_origin=to_time(sv.origin_ns),
        stream_id=sv.stream_id,
        time=float(v.time),
        phase=v.phase,
        subtask=subtask,
        score=float(v.score),
        signals=list(v.signals),
        signal_scores=[float(s) * t for s, t in zip(v.signals.values(), thresholds, strict=True)],
        signal_thresholds=list(thresholds),
        alarm=v.alarm,
        alarm_time=nan if v.alarm_time is None else float(v.alarm_time),
        onset=nan if v.onset is None else float(v.onset),
        failure_class=v.failure_class,
        classes=list(v.class_probabilities),
        probabilities=[float(p) for p in v.class_probabilities.values()],
        direction_axes=list(v.directions),
        directions=list(v.directions.values()),
        evidence_start=float(sv.evidence_start),
        evidence_end=float(v.time),
        health=v.health,
    )
    msg.header.stamp = to_time(sv.stamp_ns)
    return msg

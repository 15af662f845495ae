"""What segmenter_node publishes for one segmenter Output, in order, and the classifier's inputs.

Each word batch goes out as its Words messages (live/join.batch_messages). An applied sub-task
event goes out right after the batches of the sample it is placed at and before those of later
samples: an event waits for the next sample (live/segmenter.py), so both come in one Output, and
the classifier must see the boundary before the words that follow it. The offline replay
(live/replay.py) turns the same sequence into ClassifierSession inputs, so it classifies exactly
what classifier_node receives.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from rcbht_introspection.live.classifier import PhaseInput, WordsInput
from rcbht_introspection.live.join import LevelMessage, Watermarks, batch_messages
from rcbht_introspection.live.segmenter import Output, PhaseEvent, SegmenterSession, WordBatch
from rcbht_introspection.summaries.blocks import WrenchBlock


@dataclass(frozen=True)
class WordsOut:
    """One Words message of a batch."""

    batch: WordBatch
    message: LevelMessage
    batch_size: int
    """Messages of the batch (Words.batch_size)."""
    wrench: tuple[WrenchBlock, ...] = ()
    """The batch's wrench blocks (Words.wrench), on its first message only."""


def publication(out: Output, marks: Watermarks, now: float = 0.0) -> list[WordsOut | PhaseEvent]:
    """The messages of `out` in publication order; `marks` (the segmenter's word numbering)
    learns what went out at `now` (seconds, any clock: only idle watermarks use it)."""
    items: list[WordsOut | PhaseEvent] = []
    phases = list(out.phases)
    for batch in out.batches:
        while phases and (phases[0].stream_id, phases[0].stamp_ns) < (
            batch.stream_id,
            batch.stamp_ns,
        ):
            items.append(phases.pop(0))
        top = marks.batch(batch.arm, batch.stream_id, batch.words)
        messages = batch_messages(batch.words, top, batch.end_of_stream)
        for i, message in enumerate(messages):
            marks.published(batch.arm, batch.stream_id, message.level, top, now)
            items.append(WordsOut(batch, message, len(messages), batch.wrench if i == 0 else ()))
        if batch.end_of_stream:
            marks.ended(batch.arm, batch.stream_id)
    items.extend(phases)
    return items


def idle_marks(session: SegmenterSession[Any], marks: Watermarks, now: float) -> list[WordsOut]:
    """The empty Words messages of the levels whose numbers lag their arm's (Watermarks.due),
    at the arm's last sample; `marks` learns they went out at `now`."""
    out = []
    for arm, stream_id, level, seq_end in marks.due(now):
        if stream_id != session.stream_id or session.origin_ns is None:
            continue
        stamp = session.state[arm].last_ns
        batch = WordBatch(arm, [], stamp, session.origin_ns, stream_id)
        out.append(WordsOut(batch, LevelMessage(level, [], seq_end, False), 0))
        marks.published(arm, stream_id, level, seq_end, now)
    return out


def classifier_inputs(items: Iterable[WordsOut | PhaseEvent]) -> list[WordsInput | PhaseInput]:
    """Published messages as classifier_node's session receives them (messages.py
    words_input and phase_input, without the messages)."""
    out: list[WordsInput | PhaseInput] = []
    for item in items:
        if isinstance(item, PhaseEvent):
            stream = (item.origin_ns, item.stream_id)
            out.append(PhaseInput(item.name, item.time, item.stamp_ns, stream))
            continue
        batch, message = item.batch, item.message
        out.append(
            WordsInput(
                arm=batch.arm,
                level=message.level,
                words=list(message.words),
                now=(batch.stamp_ns - batch.origin_ns) / 1e9,
                stamp_ns=batch.stamp_ns,
                stream=(batch.origin_ns, batch.stream_id),
                batch_size=item.batch_size,
                end_of_stream=message.end_of_stream,
                seq_end=message.seq_end,
                wrench=item.wrench,
            )
        )
    return out

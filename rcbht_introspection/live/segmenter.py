"""Segmenter session: validates wrench samples, keeps one ArmStream per arm, applies sub-task events.

Stream time is seconds since the stream's first accepted sample (any arm), so absolute ROS stamps
never enter the regression fits. A sample is rejected (and counted) when its values are not all
finite or its stamp is zero or not after the arm's previous stamp. An end-of-task event finishes
every arm's stream; the next sample starts a new stream (new time origin).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.trial import SUBTASKS
from rcbht_introspection.taxonomy.words import Word

REJECT_REASONS: tuple[str, ...] = ("non_finite", "zero_stamp", "non_increasing_stamp")


@dataclass
class ArmCounts:
    """Samples of one arm accepted into the stream and rejected, by reason."""

    accepted: int = 0
    rejected: dict[str, int] = field(default_factory=lambda: dict.fromkeys(REJECT_REASONS, 0))

    @property
    def rejected_total(self) -> int:
        return sum(self.rejected.values())


@dataclass(frozen=True)
class PhaseEvent:
    """A sub-task event placed on the stream clock: `time` is the last accepted sample's time."""

    name: str
    time: float
    stamp_ns: int
    known: bool
    end: bool
    origin_ns: int | None


@dataclass
class Output:
    """What one call produced: final words per arm, and whether each arm's stream ended."""

    words: dict[str, list[Word]] = field(default_factory=dict)
    ended: bool = False
    phase: PhaseEvent | None = None
    rejected: str | None = None


class SegmenterSession:
    """One live segmentation session over `arms`; `stream_factory(arm)` builds an ArmStream."""

    def __init__(
        self,
        arms: Sequence[str],
        stream_factory: Callable[[str], object],
        end_phases: Sequence[str] = ("done",),
        subtasks: Sequence[str] = SUBTASKS,
    ) -> None:
        self.arms = tuple(arms)
        self.stream_factory = stream_factory
        self.end_phases = tuple(end_phases)
        self.subtasks = tuple(subtasks)
        self.counts = {arm: ArmCounts() for arm in self.arms}
        self.unknown_phases = 0
        self._new_stream()

    def _new_stream(self) -> None:
        self.streams = {arm: self.stream_factory(arm) for arm in self.arms}
        self.origin_ns: int | None = None
        self.last_ns = dict.fromkeys(self.arms, 0)
        self.last_t: dict[str, float | None] = dict.fromkeys(self.arms, None)
        self.first_t: dict[str, float | None] = dict.fromkeys(self.arms, None)

    def stream_time(self, stamp_ns: int) -> float:
        """Seconds since the stream's time origin."""
        assert self.origin_ns is not None
        return (stamp_ns - self.origin_ns) / 1e9

    def push(self, arm: str, stamp_ns: int, wrench: Sequence[float]) -> Output:
        """Feed one sample; returns the words it finalised, or the reason it was rejected."""
        counts = self.counts[arm]
        reason = None
        if not all(math.isfinite(v) for v in wrench):
            reason = "non_finite"
        elif stamp_ns <= 0:
            reason = "zero_stamp"
        elif stamp_ns <= self.last_ns[arm]:
            reason = "non_increasing_stamp"
        if reason is not None:
            counts.rejected[reason] += 1
            return Output(rejected=reason)
        if self.origin_ns is None:
            self.origin_ns = stamp_ns
        t = self.stream_time(stamp_ns)
        self.last_ns[arm] = stamp_ns
        self.last_t[arm] = t
        if self.first_t[arm] is None:
            self.first_t[arm] = t
        counts.accepted += 1
        words = self.streams[arm].push(t, wrench)  # type: ignore[attr-defined]
        return Output(words={arm: list(words)} if words else {})

    def phase(self, name: str) -> Output:
        """Apply a /task_phase event at each arm's last sample; an end name finishes the streams."""
        name = name.strip()
        end = name in self.end_phases
        known = end or name in self.subtasks
        if not known:
            self.unknown_phases += 1
        stamp = max(self.last_ns.values())
        t = self.stream_time(stamp) if self.origin_ns is not None else 0.0
        event = PhaseEvent(
            name=name, time=t, stamp_ns=stamp, known=known, end=end, origin_ns=self.origin_ns
        )
        out = Output(phase=event)
        if not known or self.origin_ns is None:
            return out
        for arm in self.arms:
            last, first = self.last_t[arm], self.first_t[arm]
            if end:
                out.words[arm] = list(self.streams[arm].finish())  # type: ignore[attr-defined]
            elif last is not None and first is not None and last > first:
                # a boundary at or before an arm's first sample cuts nothing
                words = self.streams[arm].mark_boundary(last, name)  # type: ignore[attr-defined]
                out.words[arm] = list(words)
        if end:
            out.ended = True
            self._new_stream()
        return out


def arm_stream_factory(
    profile: str = "reference", taxonomy_file: str = "", stream_file: str = ""
) -> Callable[[str], object]:
    """`arm -> ArmStream` with the taxonomy profile (or file) and stream config (or file)."""
    try:
        from rcbht_introspection.taxonomy.config import load_taxonomy_config
        from rcbht_introspection.taxonomy.stream import ArmStream
    except ImportError as exc:
        raise InputError(
            f"the streaming taxonomy engine is missing ({exc.name}); it comes with the taxonomy work"
        ) from None
    config = load_taxonomy_config(profile, taxonomy_file or None)
    stream_config = None
    if stream_file:
        from rcbht_introspection.config import load_yaml
        from rcbht_introspection.taxonomy.stream import StreamConfig

        stream_config = load_yaml(StreamConfig, stream_file)

    def make(arm: str) -> object:
        return ArmStream(config=config, stream_config=stream_config, arm=arm)

    return make

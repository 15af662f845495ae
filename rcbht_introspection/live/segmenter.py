"""Segmenter session: validates wrench samples, keeps one ArmStream per arm, applies sub-task events.

Stream time is seconds since the stream's first accepted sample (any arm), so absolute ROS stamps
never enter the regression fits. A sample is rejected (and counted) when its values are not all
finite, its stamp is zero or before the arm's previous stamp, or it repeats the previous stamp
(policy `IntakeConfig.repeated_stamps`, io/sensor_checks.py). The intake (live/intake.py) then
watches for a frozen sensor, subtracts a known tool's weight and a tare when configured.

A sub-task event (/task_phase) applies at each arm's last sample published before it. Wrench and
events travel on different topics, so their arrival order is not their publication order; when
both carry the publisher's source timestamp, an event waits until a later-published sample of the
arm arrives (or `flush` finds that no sample published before it is missing), which makes
replays deterministic.
An end event finishes every arm's stream; the next sample starts a new stream (new id and origin).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Generic, Protocol, TypeVar

import numpy as np

from rcbht_introspection.io.sensor_checks import FrozenWatch, spread_stamp
from rcbht_introspection.live.gravity import compensate_gravity, rotation_from_quaternion
from rcbht_introspection.live.intake import IntakeConfig, Tare
from rcbht_introspection.summaries.blocks import BlockMeans, WrenchBlock
from rcbht_introspection.taxonomy import StreamProfile
from rcbht_introspection.taxonomy.config import TaxonomyConfig, load_taxonomy_config
from rcbht_introspection.taxonomy.stream import ArmStream, load_stream_config
from rcbht_introspection.taxonomy.words import Word

RECENT_SAMPLES = 2000
"""Samples per arm remembered to place an event that arrives after later-published samples."""
REJECT_REASONS: tuple[str, ...] = (
    "non_finite",
    "zero_stamp",
    "non_increasing_stamp",
    "repeated_stamp",
    "duplicate_sample",
    "no_pose",
    "published_before_end",
)
"""non_increasing_stamp: before the previous stamp; repeated_stamp: the previous stamp with
other values (policy reject, or left over at the end of a stream with spread); duplicate_sample:
the previous stamp and values (a re-sent message); no_pose: gravity compensation is configured
and no pose of the sensor has arrived yet."""


class ArmFeed(Protocol):
    """What the session feeds per arm: an ArmStream (words), or the verifier's feed
    (verify/stream.py), which reuses the intake and event placement and returns no words."""

    def push(self, t: float, wrench6: Sequence[float]) -> list[Word]: ...

    def mark_boundary(self, t: float, subtask: str = "") -> list[Word]: ...

    def finish(self) -> list[Word]: ...


S = TypeVar("S", bound=ArmFeed)


@dataclass
class ArmCounts:
    """Samples of one arm accepted into the stream and rejected, by reason (whole session)."""

    accepted: int = 0
    rejected: dict[str, int] = field(default_factory=lambda: dict.fromkeys(REJECT_REASONS, 0))
    respaced: int = 0
    """Samples of a repeated stamp spread towards the next stamp (policy spread)."""

    @property
    def rejected_total(self) -> int:
        return sum(self.rejected.values())


@dataclass(frozen=True)
class WordBatch:
    """Words of one arm that became final at the sample `stamp_ns` of stream `stream_id`."""

    arm: str
    words: list[Word]
    stamp_ns: int
    origin_ns: int
    stream_id: int
    end_of_stream: bool = False
    wrench: tuple[WrenchBlock, ...] = ()
    """The arm's wrench blocks closed since its previous batch (summaries/blocks.py)."""


@dataclass(frozen=True)
class PhaseEvent:
    """A sub-task event placed on the stream clock: `time` is the last sample before it."""

    name: str
    time: float
    stamp_ns: int
    origin_ns: int
    stream_id: int
    end: bool


@dataclass
class Output:
    """What one call produced, in order: word batches, applied events, a rejection reason."""

    batches: list[WordBatch] = field(default_factory=list)
    phases: list[PhaseEvent] = field(default_factory=list)
    rejected: str | None = None
    unknown_phase: str | None = None


@dataclass
class _Pending:
    """An event not yet applied to every arm."""

    name: str
    source_ns: int | None
    end: bool
    waiting: set[str]
    time: float | None = None
    stamp_ns: int = 0
    late: bool = False


class _Arm(Generic[S]):
    """Per-arm stream state."""

    def __init__(self, stream: S, summaries: bool) -> None:
        self.stream = stream
        self.blocks = BlockMeans() if summaries else None
        """The wrench block means sent with the words (None: the session sends none)."""
        self.last_ns = 0
        self.last_wrench: Sequence[float] = ()
        """Values of the last sample taken at `last_ns` (accepted, or held to be spread)."""
        self.held: list[tuple[Sequence[float], int | None]] = []
        """Samples sharing `last_ns`, held until a later stamp spreads them (values, source)."""
        self.last_t: float | None = None
        self.first_t: float | None = None
        self.last_source: int | None = None
        self.recent: deque[tuple[int, float, int]] = deque(maxlen=RECENT_SAMPLES)
        """(source ns, stream time, stamp ns) of the latest samples, to place late events."""
        self.source_interval = 0.0
        """Running mean of the publication interval of this arm's samples (ns)."""
        self.finished = False


class SegmenterSession(Generic[S]):
    """One live segmentation session over `arms`; `stream_factory(arm)` builds an ArmStream
    (or another ArmFeed) for each arm of each stream."""

    def __init__(
        self,
        arms: Sequence[str],
        stream_factory: Callable[[str], S],
        end_phases: Sequence[str] = ("done",),
        subtasks: Sequence[str] | None = None,
        hold_s: float = 0.2,
        max_hold_s: float = 10.0,
        intake: IntakeConfig | None = None,
        summaries: bool = True,
    ) -> None:
        self.arms = tuple(arms)
        self.summaries = summaries
        """Send each arm's wrench block means with its word batches (the verifier's feed: no)."""
        self.intake = intake or IntakeConfig()
        self._gravity = self.intake.compensates_gravity
        self._watch_frozen = self.intake.frozen_samples > 0
        self.frozen = {
            arm: FrozenWatch(self.intake.frozen_samples, self.intake.frozen_s) for arm in self.arms
        }
        self.tares = {arm: Tare(self.intake.tare_window_s) for arm in self.arms}
        self.rotations: dict[str, np.ndarray | None] = dict.fromkeys(self.arms)
        """Latest orientation (3x3) of each arm's sensor in the world, for gravity compensation."""
        self.stream_factory = stream_factory
        self.end_phases = tuple(end_phases)
        self.subtasks = None if subtasks is None else tuple(subtasks)
        """Names that start a sub-task; None: every name that is not an end phase."""
        self.hold_ns = int(hold_s * 1e9)
        self.max_hold_ns = int(max_hold_s * 1e9)
        self.counts = {arm: ArmCounts() for arm in self.arms}
        self.unknown_phases = 0
        self.late_phases = 0
        self.bad_poses = 0
        self.pending: list[_Pending] = []
        self.end_source: int | None = None
        self.stream_id = -1
        self._new_stream()

    def _new_stream(self) -> None:
        self.state: dict[str, _Arm[S]] = {
            arm: _Arm(self.stream_factory(arm), self.summaries) for arm in self.arms
        }
        self.origin_ns: int | None = None
        self.stream_id += 1
        if self.intake.tare_at_start:
            self.tare()

    def tare(self, arms: Sequence[str] | None = None) -> None:
        """Measure a new tare of each arm (all by default) over its next samples."""
        for arm in arms or self.arms:
            self.tares[arm].request()

    def pose(self, arm: str, rotation: np.ndarray) -> None:
        """The latest orientation (3x3, sensor to world) of the arm's sensor."""
        self.rotations[arm] = rotation

    def pose_quaternion(self, arm: str, x: float, y: float, z: float, w: float) -> str:
        """The latest orientation as a quaternion; why it was ignored ('' when taken): a zero
        or non-finite quaternion is counted in `bad_poses`."""
        try:
            self.pose(arm, rotation_from_quaternion(x, y, z, w))
        except ValueError as exc:
            self.bad_poses += 1
            return str(exc)
        return ""

    def statistics(self) -> str:
        """What the session took in (samples, intake policies, events): a node's last line."""
        counts = {arm: (c.accepted, c.rejected_total) for arm, c in self.counts.items()}
        intake = {
            arm: (c.respaced, self.frozen[arm].episodes, self.tares[arm].completed)
            for arm, c in self.counts.items()
        }
        return (
            f"samples (accepted, rejected) per arm {counts}, (respaced samples, frozen episodes, "
            f"tares) per arm {intake}, unknown events {self.unknown_phases}, "
            f"late events {self.late_phases}"
        )

    # --- samples ---------------------------------------------------------------------------
    def push(
        self, arm: str, stamp_ns: int, wrench: Sequence[float], source_ns: int | None = None
    ) -> Output:
        """Feed one sample (after applying events published before it); returns what it finalised."""
        out = Output()
        if self.pending and source_ns is not None and self.origin_ns is not None:
            self._apply_due(out, lambda p: p.source_ns is not None and p.source_ns < source_ns, arm)
        counts = self.counts[arm]
        st = self.state[arm]
        reason = None
        total = sum(wrench)  # finite sum => every value finite (an overflow takes the exact check)
        if source_ns is not None and self.end_source is not None and source_ns < self.end_source:
            # a straggler of a stream that an end event already closed: it must not open a new one
            reason = "published_before_end"
        elif total - total != 0.0 and not all(math.isfinite(v) for v in wrench):
            reason = "non_finite"
        elif stamp_ns <= 0:
            reason = "zero_stamp"
        elif stamp_ns <= st.last_ns:
            reason = self._repeated(st, stamp_ns, wrench, source_ns)
            if reason is None:
                return out  # held until a later stamp spreads it
        elif self._gravity and self.rotations[arm] is None:
            reason = "no_pose"
        if reason is not None:
            counts.rejected[reason] += 1
            out.rejected = reason
            return out
        if st.held:
            self._release_held(arm, st, stamp_ns, out)
        self._accept(arm, st, stamp_ns, wrench, source_ns, out)
        return out

    def _release_held(self, arm: str, st: _Arm[S], stamp_ns: int, out: Output) -> None:
        """Accept the samples held at the previous stamp, spread evenly up to `stamp_ns`."""
        held, st.held = st.held, []
        previous = st.last_ns
        for i, (values, source) in enumerate(held, start=1):
            at = spread_stamp(previous, stamp_ns, i, len(held))
            self._accept(arm, st, int(at), values, source, out)
        self.counts[arm].respaced += len(held)

    def _repeated(
        self, st: _Arm[S], stamp_ns: int, wrench: Sequence[float], source_ns: int | None
    ) -> str | None:
        """Why a sample stamped at or before the previous one is rejected (None: held to spread)."""
        if stamp_ns < st.last_ns:
            return "non_increasing_stamp"
        if list(map(float, wrench)) == list(map(float, st.last_wrench)):
            return "duplicate_sample"
        st.last_wrench = (
            wrench  # a re-sent copy of this sample is a duplicate, as in the batch rule
        )
        if self.intake.repeated_stamps == "reject":
            return "repeated_stamp"
        st.held.append((wrench, source_ns))
        return None

    def _accept(
        self,
        arm: str,
        st: _Arm[S],
        stamp_ns: int,
        wrench: Sequence[float],
        source_ns: int | None,
        out: Output,
    ) -> None:
        """Take a valid sample into the arm's stream: intake (frozen check, gravity, tare), words."""
        origin_ns = self.origin_ns
        first_of_stream = origin_ns is None
        if origin_ns is None:
            origin_ns = self.origin_ns = stamp_ns
        t = (stamp_ns - origin_ns) / 1e9
        st.last_ns, st.last_t, st.last_wrench = stamp_ns, t, wrench
        if source_ns is not None and st.last_source is not None and source_ns > st.last_source:
            gap = source_ns - st.last_source
            st.source_interval = (
                gap if st.source_interval == 0 else 0.9 * st.source_interval + 0.1 * gap
            )
        st.last_source = source_ns
        if source_ns is not None:
            st.recent.append((source_ns, t, stamp_ns))
        if st.first_t is None:
            st.first_t = t
        self.counts[arm].accepted += 1
        if self._watch_frozen:
            self.frozen[arm].push(stamp_ns, tuple(wrench))
        values: Sequence[float] = wrench
        rotation = self.rotations[arm]
        if self._gravity and rotation is not None:  # push rejects None (no_pose)
            intake = self.intake
            values = compensate_gravity(
                wrench,
                rotation,
                intake.tool_mass_kg,
                intake.tool_com_m,
                intake.gravity_m_s2,
            ).tolist()
        tare = self.tares[arm]
        if tare.offsets is None and not tare.measuring:  # Tare.idle, inlined (per sample)
            words = self._push_tared(st, ((t, values),))
        else:
            words = self._push_tared(st, tare.push(t, values))
        if words:
            blocks = tuple(st.blocks.take()) if st.blocks is not None else ()
            out.batches.append(
                WordBatch(arm, list(words), stamp_ns, origin_ns, self.stream_id, wrench=blocks)
            )
        if first_of_stream:
            # events that came before any sample of the stream apply at its first sample
            self._apply_due(
                out, lambda p: p.source_ns is None or source_ns is None or p.source_ns < source_ns
            )

    @staticmethod
    def _push_tared(st: _Arm[S], samples: Sequence[tuple[float, Sequence[float]]]) -> list[Word]:
        """Feed samples the tare released to the arm's block means and stream; their words."""
        words: list[Word] = []
        for at, values in samples:
            if st.blocks is not None:
                st.blocks.push(at, values)
            words.extend(st.stream.push(at, values))
        return words

    # --- events ----------------------------------------------------------------------------
    def phase(self, name: str, source_ns: int | None = None) -> Output:
        """A /task_phase event; applied now unless samples published before it may be in flight."""
        out = Output()
        name = name.strip()
        end = name in self.end_phases
        if not end and self.subtasks is not None and name not in self.subtasks:
            self.unknown_phases += 1
            out.unknown_phase = name
            return out
        if end and self.origin_ns is None and not self.pending:
            return out  # nothing to finish
        self.pending.append(_Pending(name, source_ns, end, set(self.arms)))
        if self.origin_ns is None:
            return out  # applies at the stream's first sample
        if source_ns is None:
            self._apply_due(out, lambda p: True)
        else:
            # arms whose last sample was published after the event cannot wait for an earlier one
            late = [
                a
                for a, st in self.state.items()
                if st.last_source is not None and st.last_source > source_ns
            ]
            if late:
                self.late_phases += 1
                self.pending[-1].late = True
            for arm in late:
                self._apply_due(out, lambda p: p.source_ns is None or p.source_ns <= source_ns, arm)
        return out

    def flush(self, now_ns: int) -> Output:
        """Apply events that no later sample will apply (`now_ns` on the sources' clock).

        An event is due after the hold time if every waiting arm's last sample was published
        just before it (within a few sample intervals): nothing published before it is missing.
        Otherwise samples are still in flight (e.g. being repaired by reliable delivery) and it
        waits up to the maximum hold.
        """
        out = Output()
        if self.origin_ns is not None:
            self._apply_due(out, lambda p: self._flushable(p, now_ns))
        return out

    def _flushable(self, p: _Pending, now_ns: int) -> bool:
        if p.source_ns is None or p.source_ns + self.max_hold_ns <= now_ns:
            return True
        if p.source_ns + self.hold_ns > now_ns:
            return False
        for arm in p.waiting:
            st = self.state[arm]
            if st.last_source is None:
                continue
            tolerance = max(3 * st.source_interval, 10_000_000)
            if p.source_ns - st.last_source > tolerance:
                return False
        return True

    def _apply_due(
        self, out: Output, due: Callable[[_Pending], bool], only: str | None = None
    ) -> None:
        """Apply, in order, the pending events that are due (for one arm or all)."""
        for p in list(self.pending):
            if not due(p):
                break
            for arm in sorted(p.waiting):
                if only is None or arm == only:
                    self._apply(p, arm, out)
            if p.waiting:
                if p.end:
                    break  # later events belong to the next stream, whichever arm reached the end
                continue  # still due on another arm; this arm may go on with later events
            self.pending.remove(p)
            out.phases.append(
                PhaseEvent(
                    p.name, p.time or 0.0, p.stamp_ns, self.origin_ns or 0, self.stream_id, p.end
                )
            )
            if p.end:
                if p.source_ns is not None:
                    self.end_source = p.source_ns
                self._new_stream()
                break  # later events belong to the next stream: they wait for its first sample

    def _apply(self, p: _Pending, arm: str, out: Output) -> None:
        st = self.state[arm]
        p.waiting.discard(arm)
        assert self.origin_ns is not None
        at_t, at_ns = st.last_t, st.last_ns
        if p.late and p.source_ns is not None:
            # the event came after later-published samples: mark it at the sample before it
            for source, t, stamp in reversed(st.recent):
                if source < p.source_ns:
                    at_t, at_ns = t, stamp
                    break
        if p.time is None or arm == self.arms[0]:
            p.time = at_t if at_t is not None else 0.0
            p.stamp_ns = at_ns or self.origin_ns
        if p.end:
            # samples still held (a tare being measured, a repeated stamp with none after it)
            words = self._push_tared(st, self.tares[arm].release())
            if st.held:
                self.counts[arm].rejected["repeated_stamp"] += len(st.held)
                st.held = []
            words += st.stream.finish()
            st.finished = True
            wrench = tuple(st.blocks.take()) if st.blocks is not None else ()
            out.batches.append(
                WordBatch(
                    arm, list(words), st.last_ns, self.origin_ns, self.stream_id, True, wrench
                )
            )
        elif at_t is not None:
            # every sub-task start is marked (the stream reads rotation/mating starts by order)
            words = st.stream.mark_boundary(at_t, p.name)
            if words:
                wrench = tuple(st.blocks.take()) if st.blocks is not None else ()
                out.batches.append(
                    WordBatch(
                        arm, list(words), st.last_ns, self.origin_ns, self.stream_id, False, wrench
                    )
                )


def arm_stream_factory(
    profile: str = "reference",
    taxonomy_file: str = "",
    stream_file: str = "",
    stream_profile: StreamProfile = "reference",
    taxonomy: TaxonomyConfig | None = None,
) -> Callable[[str], ArmStream]:
    """`arm -> ArmStream`: taxonomy thresholds (profile of config/rcbht.yaml or of
    taxonomy_file, e.g. from `rcbht calibrate`; or a loaded `taxonomy`) and stream profile."""
    config = taxonomy or load_taxonomy_config(profile, taxonomy_file or None)
    stream_config = load_stream_config(stream_profile, stream_file or None)

    def make(arm: str) -> ArmStream:
        return ArmStream(config=config, stream_config=stream_config, arm=arm)

    return make

"""What the nodes report on /diagnostics, computed without ROS: statuses from counters.

A status is OK while nothing went wrong since the last report, WARN when a loss counter moved
(rejected samples, lost words, late or unknown events), ERROR when the node cannot do its job
(no usable model, failing predictions). Each report covers the period since the previous one.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from rcbht_introspection.io.sensor_checks import FrozenWatch
from rcbht_introspection.live.intake import Tare
from rcbht_introspection.live.segmenter import SegmenterSession
from rcbht_introspection.taxonomy.words import AXES, LEVELS, Level, Word

OK, WARN, ERROR = 0, 1, 2
"""diagnostic_msgs/DiagnosticStatus levels."""


@dataclass(frozen=True)
class Health:
    """One diagnostic status: who, how bad, why (one line), and the figures behind it."""

    name: str
    level: int
    message: str
    values: tuple[tuple[str, str], ...] = ()


class CounterWatch:
    """Remembers counters between reports and tells which of them moved."""

    def __init__(self) -> None:
        self.last: dict[str, int] = {}

    def moved(self, counts: Mapping[str, int]) -> dict[str, int]:
        """Counter -> increase since the previous call, for the counters that increased."""
        out = {k: v - self.last.get(k, 0) for k, v in counts.items() if v > self.last.get(k, 0)}
        self.last.update(counts)
        return out


@dataclass
class LatencyWindow:
    """Latencies (ms) of the current report period: p50 / p99, then a new period."""

    values: list[float] = field(default_factory=list)
    limit: int = 100_000

    def add(self, ms: float) -> None:
        if len(self.values) < self.limit:
            self.values.append(ms)

    def take(self) -> tuple[int, float, float]:
        """(count, p50, p99) of the period (NaN without values); starts a new period."""
        values, self.values = self.values, []
        if not values:
            return 0, float("nan"), float("nan")
        p50, p99 = np.percentile(values, [50, 99])
        return len(values), float(p50), float(p99)


def file_sha256(path: str) -> str:
    """Hex SHA-256 of a file ('' without a path or when it cannot be read)."""
    if not path:
        return ""
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return ""


def _moved_text(moved: Mapping[str, int]) -> str:
    return ", ".join(f"{v} {k}" for k, v in sorted(moved.items()))


class ArmHealth:
    """Per-arm intake figures of the segmenter: rate, accepted/rejected, gaps, finality backlog."""

    def __init__(self, arm: str) -> None:
        self.arm = arm
        self.watch = CounterWatch()
        self.accepted_before = 0
        self.stream_id = -1
        self.released: dict[Level, float] = {}
        """Per level, the end of the newest word released in the current stream (seconds)."""

    def words(self, stream_id: int, words: list[Word]) -> None:
        """Note the words of a published batch (for the finality backlog)."""
        if stream_id != self.stream_id:
            self.stream_id, self.released = stream_id, {}
        for w in words:
            if w.end > self.released.get(w.level, -np.inf):
                self.released[w.level] = w.end

    def report(
        self,
        period_s: float,
        accepted: int,
        rejected: Mapping[str, int],
        intake: Mapping[str, int],
        last_t: float | None,
        active: bool,
        frozen: FrozenWatch | None = None,
        tare: Tare | None = None,
        respaced: int = 0,
        pose: str = "",
    ) -> Health:
        """The arm's status for the period that just ended (WARN also while the sensor is frozen)."""
        rate = (accepted - self.accepted_before) / period_s if period_s > 0 else 0.0
        self.accepted_before = accepted
        losses = {f"rejected {k}": v for k, v in rejected.items()}
        losses.update({k: v for k, v in intake.items() if v})
        if frozen is not None:
            losses["frozen episodes"] = frozen.episodes
        moved = self.watch.moved(losses)
        values = [("input rate (Hz)", f"{rate:.1f}"), ("samples accepted", str(accepted))]
        values += [(f"samples {k}", str(v)) for k, v in losses.items() if k != "frozen episodes"]
        values += sensor_values(frozen, tare, respaced)
        if pose:
            values.append(("sensor pose", pose))
        for word_level in LEVELS:
            backlog = (
                last_t - self.released[word_level]
                if last_t is not None and word_level in self.released
                else float("nan")
            )
            values.append((f"finality backlog {word_level.value} (s)", f"{backlog:.3f}"))
        if frozen is not None and frozen.frozen:
            level, message = WARN, frozen.describe(self.arm)
            if moved:
                message += f"; {_moved_text(moved)} in the last period"
        elif moved:
            level, message = WARN, f"arm {self.arm}: {_moved_text(moved)} in the last period"
        elif active and rate == 0:
            level, message = OK, f"arm {self.arm}: waiting for wrench"
        else:
            level, message = OK, f"arm {self.arm}: {rate:.0f} samples/s"
        return Health(f"segmenter_node: arm {self.arm}", level, message, tuple(values))


def sensor_values(
    frozen: FrozenWatch | None, tare: Tare | None, respaced: int
) -> list[tuple[str, str]]:
    """/diagnostics values of an arm's sensor intake: spread stamps, frozen sensor, tare."""
    values = [("samples respaced (repeated stamp)", str(respaced))]
    if frozen is not None:
        values += [
            ("frozen now", "yes" if frozen.frozen else "no"),
            ("frozen episodes", str(frozen.episodes)),
            ("frozen samples", str(frozen.frozen_samples)),
        ]
    if tare is not None:
        offsets = (
            "none"
            if tare.offsets is None
            else " ".join(f"{a}={v:.4g}" for a, v in zip(AXES, tare.offsets, strict=True))
        )
        values += [
            ("tares completed", str(tare.completed)),
            ("tare measuring", "yes" if tare.measuring else "no"),
            ("tare offsets", offsets),
        ]
    return values


def segmenter_health(
    session: SegmenterSession[Any],
    arms: Mapping[str, ArmHealth],
    period_s: float,
    active: bool,
    watch: CounterWatch,
) -> list[Health]:
    """segmenter_node's statuses: per arm intake (rate, accepted/rejected, gaps, finality
    backlog, frozen sensor, tare, pose with gravity compensation), then the events."""
    out = []
    frozen_checks, gravity = session.intake.frozen_samples > 0, session.intake.compensates_gravity
    for arm, health in arms.items():
        st, counts = session.state[arm], session.counts[arm]
        pose = ("none yet" if session.rotations[arm] is None else "received") if gravity else ""
        out.append(
            health.report(
                period_s,
                counts.accepted,
                counts.rejected,
                vars(st.stream.counters),
                st.last_t,
                active,
                session.frozen[arm] if frozen_checks else None,
                session.tares[arm],
                counts.respaced,
                pose,
            )
        )
    events = {
        "unknown events": session.unknown_phases,
        "late events": session.late_phases,
        "pending events": len(session.pending),
        "poses ignored": session.bad_poses,
    }
    out.append(events_health("segmenter_node", events, watch))
    return out


def events_health(node: str, counts: Mapping[str, int], watch: CounterWatch) -> Health:
    """Sub-task events: WARN when late, unknown or ignored events were counted in the period."""
    moved = watch.moved(counts)
    values = tuple((k, str(v)) for k, v in counts.items())
    if moved:
        return Health(f"{node}: events", WARN, f"{_moved_text(moved)} in the last period", values)
    return Health(f"{node}: events", OK, "events in order", values)


class ModelStatus(NamedTuple):
    """The classifier's model for /diagnostics."""

    file: str
    sha256: str
    problem: str
    """Why no model is used ('' when one is)."""
    prediction_error: str | None
    """The latest prediction error (None: none)."""


def classifier_health(
    state: str,
    model: ModelStatus,
    latency: LatencyWindow,
    counts: Mapping[str, int],
    watch: CounterWatch,
    extra: Sequence[tuple[str, str]] = (),
) -> Health:
    """The classifier's status: model, belief-update latency of the period, word losses;
    `extra` values (teaching) go after them."""
    model_file, model_sha256, model_problem, prediction_error = model
    n, p50, p99 = latency.take()
    moved = watch.moved(counts)
    values = (
        ("lifecycle state", state),
        ("model file", model_file or "(none)"),
        ("model sha256", model_sha256),
        ("belief updates in period", str(n)),
        ("belief update latency p50 (ms)", f"{p50:.3f}"),
        ("belief update latency p99 (ms)", f"{p99:.3f}"),
        *((k, str(v)) for k, v in counts.items()),
        *extra,
    )
    if model_problem:
        level, message = ERROR, f"no usable model, publishing 'unknown': {model_problem}"
    elif prediction_error:
        level, message = ERROR, f"model prediction failed: {prediction_error}"
    elif moved:
        level, message = WARN, f"{_moved_text(moved)} in the last period"
    else:
        level, message = OK, f"{state}, {n} belief updates in the last period"
    return Health("classifier_node: belief", level, message, values)


def outputs_health(name: str, words: int, phases: int, intake: int) -> Health:
    """Subscribers matched to segmenter_node's outputs (the fewest of any word topic, the
    events) and publishers to its inputs: a harness waits for them before it plays a bag."""
    values = (
        ("word subscribers matched", str(words)),
        ("phase subscribers matched", str(phases)),
        ("intake publishers matched", str(intake)),
    )
    return Health(f"{name}: outputs", OK, f"{words} subscribers on every word topic", values)

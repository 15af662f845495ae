"""What a characteriser reads of a trial or a stream: one vector per tick in its view, and the
reference and context the evidence starts from (verify/characterise.py says why)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from rcbht_introspection.verify.characterise import VIEWS, RunningEvidence
from rcbht_introspection.verify.detector import Detector
from rcbht_introspection.verify.features import PER_ARM, TrialFeatures, kind_columns
from rcbht_introspection.verify.novelty import NominalLevel, TimingModel


class Reading(NamedTuple):
    """What a characteriser names the class from at one tick."""

    time: float
    features: np.ndarray
    """The span summaries, context and where the task stands (`RunningEvidence.features`)."""
    window: np.ndarray
    """The ticks since onset minus the reference (`RunningEvidence.window`)."""


class Tick(NamedTuple):
    """One tick as a characteriser keeps it."""

    time: float
    phase: str
    """The commanded sub-task ('' before the first)."""
    elapsed: float
    vector: np.ndarray
    """The view's vector (`EvidenceReader.vector`)."""


@dataclass(frozen=True)
class EvidenceReader:
    """A view of the ticks: which vector each gives, and where the evidence starts from."""

    view: str
    phases: tuple[str, ...]
    """The sub-tasks of the nominal model (the context's one-hot)."""
    n_arms: int
    level: NominalLevel | None = None
    timing: TimingModel | None = None

    def __post_init__(self) -> None:
        if self.view not in VIEWS:
            raise ValueError(f"unknown evidence view {self.view!r}")
        if self.view == "timing" and self.timing is None:
            raise ValueError("the timing view needs a timing model")

    def vector(
        self, features: np.ndarray, names: Sequence[str], starts: Sequence[float], t: float
    ) -> np.ndarray:
        """The view's vector of a tick, from its features and the sub-tasks started so far: the
        verifier's is the mean wrench minus the successes' at that time into the sub-task, and
        the wrench's spread over the window (stick-slip, vibration)."""
        if self.view == "timing" and self.timing is not None:
            return self.timing.z_row(names, starts, t)
        mean: np.ndarray = np.asarray(features)[kind_columns("mean", self.n_arms)]
        if self.view != "wrench":
            return mean
        nominal = self.level.at(names[-1], t - starts[-1]) if self.level and names else None
        spread = np.asarray(features)[kind_columns("std", self.n_arms)]
        return np.concatenate([mean - nominal if nominal is not None else mean, spread])

    def ticks(self, tf: TrialFeatures) -> list[Tick]:
        """Every tick of a trial in this view."""
        out = []
        for t in range(len(tf.times)):
            i = int(tf.phase_index[t])
            g = float(tf.times[t])
            vec = self.vector(tf.features[t], tf.phases[: i + 1], list(tf.starts[: i + 1]), g)
            out.append(Tick(g, tf.phases[i] if i >= 0 else "", float(tf.elapsed[t]), vec))
        return out

    def now(self, tick: Tick, onset: float) -> np.ndarray:
        """Where the task stands at a tick (the verifier's view): the sub-task running (one-hot
        over the nominal ones), the time into it and the time since onset."""
        if self.view != "wrench":
            return np.zeros(0)
        onehot = [float(tick.phase == p) for p in self.phases]
        return np.array([*onehot, tick.elapsed, tick.time - onset])

    def begin(
        self, spans: Sequence[float], onset: float, ticks: Sequence[Tick], lead: float = 0.0
    ) -> RunningEvidence:
        """The evidence from `onset` on, started from the ticks kept so far (those at or after
        onset are added); the reference is the last tick before `onset - lead` (the first if
        none)."""
        at = onset - lead - 1e-9
        ref = next((k for k in reversed(ticks) if k.time < at), ticks[0] if ticks else None)
        first = next((k for k in ticks if k.time >= onset - 1e-9), ref)
        width = len(ref.vector) if ref is not None else 0
        reference, context = np.zeros(width), np.zeros(0)
        if self.view == "wrench" and ref is not None and first is not None:
            reference = ref.vector
            onehot = np.array([float(first.phase == p) for p in self.phases])
            context = np.concatenate([ref.vector, [first.elapsed], onehot])
        elif self.view == "raw":
            context = np.array([onset])
        evidence = RunningEvidence(tuple(spans), onset, reference, context)
        if first is not None:
            evidence.now = self.now(first, onset)
        for k in ticks:
            if k.time >= onset - 1e-9:
                evidence.add(k.time, k.vector, self.now(k, onset))
        return evidence


def namings(
    reader: EvidenceReader,
    spans: Sequence[float],
    onset: float,
    ticks: Sequence[Tick],
    start: float,
    lead: float = 0.0,
) -> list[Reading]:
    """The evidence at every tick a characteriser names the class again: the first at or after
    `start` (the alarm; the evidence begins at onset, its reference `lead` before), then each
    tick that opens a span, then the last tick."""
    before = [k for k in ticks if k.time < start - 1e-9]
    later = [k for k in ticks if k.time >= start - 1e-9]
    if not later:
        return []
    evidence = reader.begin(spans, onset, [*before, later[0]], lead)
    out = [Reading(later[0].time, evidence.features(), evidence.window())]
    for k in later[1:]:
        if evidence.add(k.time, k.vector, reader.now(k, onset)):
            out.append(Reading(k.time, evidence.features(), evidence.window()))
    if out[-1].time != later[-1].time:
        out.append(Reading(later[-1].time, evidence.features(), evidence.window()))
    return out


def named_at(namings_: Sequence[tuple[float, str]], t: float) -> str:
    """The class named at time t: the last naming at or before t ('' before the first)."""
    found = ""
    for when, cls in namings_:
        if when > t + 1e-9:
            break
        found = cls
    return found


def arms_of(tf: TrialFeatures) -> int:
    """Number of arms of a trial's features."""
    arms: int = tf.features.shape[1] // PER_ARM
    return arms


def reader_of(detector: Detector, view: str, n_arms: int) -> EvidenceReader:
    """The evidence view of a method over its detector's models."""
    m = detector.models
    return EvidenceReader(view, detector.phases, n_arms, m.level, m.timing)

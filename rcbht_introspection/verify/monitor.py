"""The live verifier: wrench samples and sub-task events in, one verdict per tick out.

The verifier node's state without ROS. Each tick (every step_s of stream time, once every arm's
samples have passed it) gets the detector's signals against their thresholds; the first tick
above threshold raises the alarm, which latches until the stream ends. From then on each verdict
carries the failure class, its probabilities and the deviation directions, named again as each
evidence span closes. The same numbers as the offline `Detector.run` on the whole trial and the
offline namings (tested).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from rcbht_introspection.verify.characterise import RunningEvidence
from rcbht_introspection.verify.detector import SCORE_CAP
from rcbht_introspection.verify.evidence import Tick, reader_of
from rcbht_introspection.verify.features import PER_ARM, ArmFeatures, SubtaskDeparture
from rcbht_introspection.verify.mismatch import MISMATCH, Contradiction, mismatch_onset
from rcbht_introspection.verify.model_file import VerifierModel

NOMINAL = "nominal"
ANOMALY = "anomaly"
MAX_ARM_LAG_TICKS = 20
"""An arm this many ticks behind the others (1 s at 20 Hz) is held, so verdicts do not stall."""
HISTORY_TICKS = 20_000
"""Ticks kept before the alarm for the evidence from onset on (1000 s at 20 Hz): an onset
further back than this is read from the ticks kept. After the alarm the evidence is running
sums (`RunningEvidence`), whatever its length."""
VERIFIER_VIEW = "wrench"


@dataclass(frozen=True)
class Verdict:
    """The verifier's judgement at one tick."""

    time: float
    phase: str
    """The commanded sub-task running at this tick ('' before the first event)."""
    score: float
    """Largest signal over its threshold (> 1: above threshold)."""
    signals: dict[str, float]
    """Each signal over its threshold."""
    alarm: bool
    """Latched: the alarm has fired in this stream."""
    thresholds: dict[str, float] = field(default_factory=dict)
    """Each signal's threshold at this tick (its sub-task's, in the signal's own units)."""
    alarm_time: float | None = None
    onset: float | None = None
    failure_class: str = ""
    class_probabilities: dict[str, float] = field(default_factory=dict)
    directions: dict[str, str] = field(default_factory=dict)

    @property
    def health(self) -> str:
        """What a planner switches on: 'nominal', 'anomaly' (alarm, no class yet) or the class."""
        if not self.alarm:
            return NOMINAL
        return self.failure_class or ANOMALY


class VerifierSession:
    """One stream's verifier state; `reset` starts the next stream."""

    def __init__(self, model: VerifierModel) -> None:
        self.model = model
        self.reset()

    def reset(self) -> None:
        cfg = self.model.config
        self.arms = {a: ArmFeatures(cfg) for a in self.model.arms}
        self.pending: dict[str, dict[int, tuple[float, np.ndarray]]] = {a: {} for a in self.arms}
        self.last_rows = {a: np.zeros(PER_ARM) for a in self.arms}
        d = self.model.detector
        self.reader = reader_of(d, VERIFIER_VIEW, len(self.arms))
        self.departure = SubtaskDeparture(d.models.lag, len(self.arms))
        """The running sub-task's reference level (the `departure` signal)."""
        self.held_rows = 0
        """Ticks at which an arm had sent nothing for MAX_ARM_LAG_TICKS while another had:
        its last row stood in (counted, not silent)."""
        self.phases: list[tuple[str, float]] = []
        self.alarm_time: float | None = None
        self.onset: float | None = None
        self._excursion: float | None = None
        """First tick of the running excursion above onset_fraction (the onset estimate)."""
        self._prev_below = False
        self.tick = 0
        self.history: list[Tick] = []
        """The ticks before the alarm: where the characterisation's evidence begins."""
        self.evidence: RunningEvidence | None = None
        """From the alarm on: the evidence [onset, now]."""
        self.named: tuple[str, dict[str, float], dict[str, str]] | None = None
        """The characteriser's latest naming (class, probabilities, directions)."""
        self.ended = False
        self.contradictions: list[Contradiction] = []
        """Final verdicts that contradicted their sub-task (the mismatch signal's evidence)."""

    def contradict(self, contradiction: Contradiction) -> None:
        """A final verdict contradicted its commanded sub-task: the mismatch signal counts it
        from the first tick at or after `contradiction.time`."""
        self.contradictions.append(contradiction)

    def phase(self, name: str, t: float) -> None:
        """A sub-task event at stream time t (applies to samples after it)."""
        self.phases.append((name, t))

    def push(self, arm: str, t: float, wrench: Sequence[float] | np.ndarray) -> list[Verdict]:
        """One wrench sample of `arm`; returns the verdicts of the ticks now complete on all arms."""
        if arm not in self.arms or self.ended:
            return []
        feats = self.arms[arm]
        for g, row in feats.push(float(t), np.asarray(wrench, dtype=float)):
            self.pending[arm][round(g / self.model.config.step_s)] = (g, row)
        return self._complete()

    def end(self) -> list[Verdict]:
        """The stream ended (the end event): the last rows, with the last sub-task's duration."""
        if self.ended:
            return []
        for arm, feats in self.arms.items():
            for g, row in feats.flush():
                self.pending[arm][-1] = (g, row)
        self.ended = True
        return self._complete(final=True)

    def _complete(self, final: bool = False) -> list[Verdict]:
        out = []
        while True:
            missing = [a for a, p in self.pending.items() if self.tick not in p]
            if missing:
                ahead = max((max(p) for p in self.pending.values() if p), default=-1)
                if ahead < self.tick + MAX_ARM_LAG_TICKS:
                    break
                for a in missing:  # a silent arm: hold its last row rather than stall
                    self.pending[a][self.tick] = (
                        self.tick * self.model.config.step_s,
                        self.last_rows[a],
                    )
                    self.held_rows += 1
            rows = [self.pending[a].pop(self.tick) for a in self.arms]
            for a, (_, row) in zip(self.arms, rows, strict=True):
                self.last_rows[a] = row
            self.tick += 1
            out.append(self._verdict(rows[0][0], np.concatenate([r for _, r in rows]), False))
        if final and all(-1 in p for p in self.pending.values()):
            rows = [self.pending[a].pop(-1) for a in self.arms]
            out.append(self._verdict(rows[0][0], np.concatenate([r for _, r in rows]), True))
        return out

    def _verdict(self, g: float, features: np.ndarray, last: bool) -> Verdict:
        """The verdict of the tick at stream time `g` (`last`: the row at the stream's end)."""
        d = self.model.detector
        i, name, elapsed = self._phase_at(g)
        starts = [s for _, s in self.phases]
        scores = self._signal_scores(g, features, last)
        min_p = d.config.mismatch_min_probability
        signals = (*d.signals, MISMATCH)
        thresholds = np.append(d.threshold_of(name), min_p)
        normalised = np.append(np.asarray(scores) / thresholds[:-1], self._mismatch(g, min_p))
        combined = float(np.nan_to_num(normalised.max(), posinf=1e6))
        names = [n for n, _ in self.phases[: i + 1]]
        tick = Tick(g, name, elapsed, self.reader.vector(features, names, starts[: i + 1], g))
        rename = self._keep(tick) or last
        if self.alarm_time is None:
            rename = self._watch(g, combined, normalised) or rename
        verdict = Verdict(
            time=g,
            phase=name,
            score=combined,
            signals={s: float(v) for s, v in zip(signals, normalised, strict=True)},
            thresholds={s: float(v) for s, v in zip(signals, thresholds, strict=True)},
            alarm=self.alarm_time is not None,
            alarm_time=self.alarm_time,
            onset=self.onset,
        )
        return self._named(verdict, rename)

    def _phase_at(self, g: float) -> tuple[int, str, float]:
        """Index, name and elapsed time of the sub-task running at `g` (-1, '', 0.0: none yet)."""
        starts = [s for _, s in self.phases]
        i = int(np.searchsorted(starts, g, side="right")) - 1
        name = self.phases[i][0] if i >= 0 else ""
        elapsed = g - self.phases[i][1] if i >= 0 else 0.0
        return i, name, elapsed

    def _signal_scores(self, g: float, features: np.ndarray, last: bool) -> list[float]:
        """The detector's signals at `g`, in its units and capped (0 before the first event);
        at the `last` row the running sub-task's duration counts as ended."""
        d = self.model.detector
        i, name, elapsed = self._phase_at(g)
        starts = [s for _, s in self.phases]
        # every tick of a model with the signal, as departure_features feeds them
        departure = self.departure.row(i, features) if d.models.departure is not None else None
        scores = []
        for s in d.signals:
            neighbours = d.models.neighbours_for(s)
            if neighbours is not None:
                v = neighbours.score_row(name, elapsed, features) if i >= 0 else 0.0
                scores.append(min(v, SCORE_CAP))
            elif s == "departure" and d.models.departure is not None and departure is not None:
                v = d.models.departure.score_row(name, elapsed, departure) if i >= 0 else 0.0
                scores.append(min(v, SCORE_CAP))
            elif s == "timing" and d.models.timing is not None:
                tm = d.models.timing
                v = tm.running(name, elapsed) if i >= 0 else 0.0
                if i > 0:
                    v = max(v, tm.ended(self.phases[i - 1][0], starts[i] - starts[i - 1]))
                if last and i >= 0:
                    v = max(v, tm.ended(name, g - starts[i]))
                scores.append(min(v, SCORE_CAP))
            else:
                raise ValueError(f"signal {s!r} is not in the verifier model")
        return scores

    def _mismatch(self, g: float, min_p: float) -> float:
        """The mismatch signal at `g`: the strongest contradiction so far over `min_p`."""
        return max(
            (c.probability / min_p for c in self.contradictions if c.time <= g + 1e-9),
            default=0.0,
        )

    def _keep(self, tick: Tick) -> bool:
        """Keep `tick` for the characterisation: as evidence after the alarm (whether a span
        closed, so the class is named again), in the bounded history before it."""
        if self.evidence is not None:
            now = self.reader.now(tick, self.evidence.onset)
            return self.evidence.add(tick.time, tick.vector, now)
        if self.alarm_time is None:
            self.history.append(tick)
            if len(self.history) > HISTORY_TICKS:
                del self.history[: len(self.history) - HISTORY_TICKS]
        return False

    def _watch(self, g: float, combined: float, normalised: np.ndarray) -> bool:
        """Before the alarm: track the excursion (the onset estimate) and raise the alarm once
        the combined score passes 1; whether it was raised at this tick."""
        raised = False
        if self._excursion is None or self._prev_below:
            self._excursion = g  # a tick below onset_fraction ended the previous excursion
        if combined > 1.0:
            self.alarm_time = g
            self.onset = self._excursion
            if int(np.nanargmax(np.nan_to_num(normalised, posinf=1e6))) == len(normalised) - 1:
                # raised by the mismatch: the evidence is the contradicted sub-task
                start = mismatch_onset(
                    self.contradictions, g, self.model.detector.config.mismatch_min_probability
                )
                if start is not None:  # 0.0 is a start (the first sub-task's)
                    self.onset = start
            self._start_evidence(self.onset)
            raised = True
        self._prev_below = combined < self.model.detector.config.onset_fraction
        return raised

    def _named(self, verdict: Verdict, rename: bool) -> Verdict:
        """`verdict` with the characteriser's naming once the evidence runs, named again when
        `rename` (a span closed, the alarm, the stream's end)."""
        ch = self.model.characteriser
        if self.evidence is None or ch is None:
            return verdict
        if rename or self.named is None:
            self.named = ch.characterise(self.evidence.features(), self.evidence.window())
        cls, probs, dirs = self.named
        return Verdict(
            **{
                **verdict.__dict__,
                "failure_class": cls,
                "class_probabilities": probs,
                "directions": dirs,
            }
        )

    def _start_evidence(self, onset: float) -> None:
        """At the alarm: the evidence from the kept ticks, the alarm's among them (later ones
        are added as they come)."""
        if self.model.characteriser is not None:
            config = self.model.config
            self.evidence = self.reader.begin(config.evidence_s, onset, self.history, config.lag_s)
        self.history = []

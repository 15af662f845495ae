"""The reference planner without ROS: verdicts and attempt results in, decisions out.

One Planner runs one trial: it starts attempts, aborts the running one when its policy reads an
alarm, and picks the next attempt's correction from the recovery table, until the arm's own
seat check passes or the attempts run out. planner_node and `rcbht closed-loop` drive the same
class, so their decisions are the same for the same verdicts and results.

Policies: `none` (one attempt), `retry` (the same plan again after the arm's own failure),
`search` (a blind grid search of corrections after the arm's own failure), `introspect` (abort
on the verifier's alarm, recover from the named class and directions), `oracle` (abort on the
alarm, then the true correction: the upper bound).
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal, get_args

from rcbht_introspection.plan.recovery import (
    ANOMALY,
    VERDICT_AXES,
    ClassRecovery,
    Correction,
    RecoveryConfig,
)

PolicyName = Literal["none", "retry", "search", "introspect", "oracle"]
POLICIES: tuple[str, ...] = get_args(PolicyName)
READS_VERDICTS = ("introspect", "oracle")
"""Policies that abort on the verifier's alarm."""
DecisionKind = Literal["attempt", "abort", "stop"]


@dataclass(frozen=True)
class Report:
    """How an attempt ended, as the arm reports it: its own seat check, and why."""

    seated: bool
    reason: str
    """seated, timeout, no_snap (the arm's own checks), aborted (cancelled), rejected."""


@dataclass(frozen=True)
class Steps:
    """One failure class's learnt correction steps per correction axis (x, y, yaw): `size`
    first (the median labelled deviation), then `spread` when that missed (half their 10-90 %
    range), halved at each later miss."""

    size: dict[str, float] = field(default_factory=dict)
    spread: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Hypothesis:
    """A class the verifier gave the clean attempt, its probability and its directions."""

    failure_class: str
    probability: float
    directions: dict[str, str]


MAX_HYPOTHESES = 3
"""Classes of the clean attempt's verdict kept as hypotheses (the likeliest first)."""
REFINE_SHARE = 0.5
"""A refinement along the named directions weighs its hypothesis's probability as a `try`
class with one of two candidates left."""
_SIGNED_AXES = re.compile(r"([a-z])([+-])")


def _family(failure_class: str) -> str:
    return failure_class.split("_", 1)[0]


def _signed(failure_class: str) -> dict[str, str] | None:
    """The signed axes a class's name carries (`deviation_x+y-`), None when it has none."""
    _, _, dirs = failure_class.partition("_")
    signed = dict(_SIGNED_AXES.findall(dirs))
    if dirs and "".join(f"{a}{d}" for a, d in signed.items()) == dirs:
        return signed
    return None


def _directions(failure_class: str, verdict: Mapping[str, str]) -> dict[str, str]:
    """A class's directions: its name's signed axes (`deviation_x+y-`), else the verdict's."""
    signed = _signed(failure_class)
    return dict(verdict) if signed is None else signed


def _hypotheses(
    named: str, directions: Mapping[str, str], probabilities: Mapping[str, float]
) -> list[Hypothesis]:
    """The named class first, then the other likeliest ones with a probability above 0; each
    with the verdict's directions unless its name carries its own."""
    ranked = sorted(probabilities.items(), key=lambda kv: -kv[1])
    classes = [named, *(c for c, p in ranked if c != named and p > 0)][:MAX_HYPOTHESES]
    return [
        Hypothesis(
            c,
            float(probabilities.get(c, 1.0 if c == named else 0.0)),
            _directions(c, directions),
        )
        for c in classes
    ]


@dataclass(frozen=True)
class Decision:
    """One decision of the planner: start attempt n with a correction, abort it, or stop."""

    kind: DecisionKind
    attempt: int
    time: float
    """Seconds into the attempt (0 for an attempt's start)."""
    correction: Correction = field(default_factory=Correction)
    failure_class: str = ""
    reason: str = ""

    def to_dict(self) -> dict[str, object]:
        return {
            "kind": self.kind,
            "attempt": self.attempt,
            "time": round(self.time, 6),
            "correction": {a: round(v, 7) for a, v in self.correction.as_dict().items()},
            "failure_class": self.failure_class,
            "reason": self.reason,
        }


def search_grid(step: Mapping[str, float]) -> Iterator[Correction]:
    """The blind search's corrections in order: one axis at +-step first, then pairs, then all,
    then the same rings at twice the step, and so on."""
    axes = [a for a in ("x", "y", "yaw") if a in step]
    for ring in itertools.count(1):
        for n in range(1, len(axes) + 1):
            for chosen in itertools.combinations(axes, n):
                for signs in itertools.product((1.0, -1.0), repeat=n):
                    yield Correction.of(
                        {a: s * ring * step[a] for a, s in zip(chosen, signs, strict=True)}
                    )


class Planner:
    """One trial's decisions under a policy (see the module's docstring)."""

    def __init__(
        self,
        policy: PolicyName,
        recovery: RecoveryConfig,
        steps: Mapping[str, Steps] | None = None,
        truth: Correction | None = None,
    ) -> None:
        if policy not in POLICIES:
            raise ValueError(f"unknown policy {policy!r} (known: {', '.join(POLICIES)})")
        if policy == "oracle" and truth is None:
            raise ValueError("the oracle policy needs the trial's true correction")
        self.policy = policy
        self.recovery = recovery
        self.steps = dict(steps or {})
        """Learnt steps per failure class (the verifier file's labelled deviations)."""
        self.truth = truth
        self.grid = search_grid(recovery.search_step)
        self.attempt = 0
        self.correction = Correction()
        self.decisions: list[Decision] = []
        self._steps: dict[str, list[float]] = {}
        """Per correction axis, the steps moved along it for the current hypothesis."""
        self._mirrored: set[str] = set()
        """Correction axes already tried on their other side."""
        self._tried: dict[str, int] = {}
        """Per class of a `try` recovery: the candidates tried so far."""
        self._hypotheses: list[Hypothesis] = []
        """The clean attempt's classes, likeliest first: what introspect recovers from."""
        self._current = 0
        self._ranked: dict[str, float] = {}
        self._alarm_at: float | None = None
        self._aborted: Decision | None = None
        self._named: tuple[str, dict[str, str]] | None = None
        """The verifier's latest class and directions on the running attempt."""

    @property
    def reads_verdicts(self) -> bool:
        return self.policy in READS_VERDICTS

    def first(self) -> Decision:
        """The first attempt, uncorrected."""
        return self._start(Correction(), "first attempt")

    def verdict(
        self,
        time: float,
        alarm: bool,
        failure_class: str,
        directions: Mapping[str, str],
        probabilities: Mapping[str, float] | None = None,
    ) -> Decision | None:
        """A verdict on the running attempt: the abort, when the policy reacts to it.

        Both verdict policies abort only the uncorrected plan: a corrected attempt departs from
        the nominal wrench by design, so its alarms say little about whether it will seat; it
        runs to the arm's own end. The oracle aborts at the alarm; introspect lets the verifier
        name the class for naming_wait_s first, keeps its classes ranked by probability as
        the hypotheses to recover from, and the latest naming of every later attempt."""
        if not self.reads_verdicts or self._aborted is not None or not alarm:
            return None
        if self._alarm_at is None:
            self._alarm_at = time
        if failure_class not in ("", ANOMALY):
            self._named = (failure_class, dict(directions))
            self._ranked = dict(probabilities or {failure_class: 1.0})
        if self.correction != Correction():
            return None
        if self.policy == "introspect" and time - self._alarm_at < self.recovery.naming_wait_s:
            return None
        cls, dirs = self._named or (ANOMALY, {})
        self._hypotheses = _hypotheses(cls, dirs, self._ranked) if self._named else []
        self._current = 0
        signs = ",".join(f"{a}{d}" for a, d in sorted(dirs.items()) if d in "+-")
        self._aborted = Decision("abort", self.attempt, time, self.correction, cls, signs)
        self.decisions.append(self._aborted)
        return self._aborted

    def ended(self, report: Report, time: float) -> Decision:
        """The running attempt ended: the next attempt, or stop."""
        if report.seated:
            return self._stop(time, "seated")
        if self.policy == "none" or self.attempt >= self.recovery.max_attempts:
            return self._stop(time, f"gave up after {report.reason}")
        nxt = self._next_correction().clipped(self.recovery.bounds)
        return self._start(nxt, f"after {report.reason}")

    def _next_correction(self) -> Correction:
        if self.policy == "retry":
            return self.correction
        if self.policy == "search":
            return next(self.grid)
        if self.policy == "oracle":
            assert self.truth is not None
            return self.truth
        if not self._hypotheses:  # introspect, nothing named: the same plan again
            return self.correction
        if self.correction == Correction():  # the clean attempt was aborted: the likeliest
            return self._recover(self._hypotheses[0])
        return self._after_failed_recovery()

    def _after_failed_recovery(self) -> Correction:
        """A corrected attempt failed. Refine the current hypothesis when its attempt was named
        with its family again and refining is worth more than the next hypothesis (a `try`'s
        remaining candidates weigh its probability by their share, a refinement along the named
        directions by REFINE_SHARE): a correction along a wrong hypothesis makes an error of
        that very family, so the naming alone proves little. Else recover from the next
        hypothesis, from the clean plan."""
        h = self._hypotheses[self._current]
        entry = self.recovery.recovery_of(h.failure_class)
        named = self._named
        same = named is not None and _family(named[0]) == _family(h.failure_class)
        nxt = (
            self._hypotheses[self._current + 1]
            if self._current + 1 < len(self._hypotheses)
            else None
        )
        refine = same and entry.action == "undo_direction" and any(self._steps.values())
        worth = nxt is None or h.probability * REFINE_SHARE >= nxt.probability
        if refine and worth and named is not None:
            dirs = _directions(*named)
            if _signed(h.failure_class) is None and (other := self._other_side()):
                return other
            return self._undo(named[0], entry, self.correction, dirs)
        tried = self._tried.get(h.failure_class, 0)
        left = len(entry.candidates) - tried if entry.action == "try" or tried else 0
        share = left / len(entry.candidates) if entry.candidates else 0.0
        if left > 0 and (nxt is None or (same and h.probability * share >= nxt.probability)):
            return self._recover(h)
        if nxt is None:
            return self.correction
        self._current += 1
        return self._recover(nxt)

    def _recover(self, h: Hypothesis) -> Correction:
        """The first correction for hypothesis `h`, from the clean plan: against its directions,
        else its table's next candidate."""
        entry = self.recovery.recovery_of(h.failure_class)
        self._steps, self._mirrored = {}, set()
        if entry.action == "undo_direction":
            out = self._undo(h.failure_class, entry, Correction(), h.directions)
            if out != Correction() or not entry.candidates:
                return out
        if entry.action != "retry" and entry.candidates:
            tries = self._tried.get(h.failure_class, 0)
            self._tried[h.failure_class] = tries + 1
            out = Correction()
            for axis, value in entry.candidates[tries % len(entry.candidates)].items():
                out = out.moved(axis, value)
            return out
        return Correction()

    def _other_side(self) -> Correction | None:
        """The correction mirrored on each axis moved once: a side read from the verdict, not
        the class's name, may be a guess the wrench could not confirm, and a naming after the
        miss is as ambiguous (a flip means overshoot or the wrong side), so the other side at
        the same size comes first (once per axis; None when no axis qualifies)."""
        out = self.correction
        for axis in VERDICT_AXES.values():
            if len(self._steps.get(axis, ())) == 1 and axis not in self._mirrored:
                out = out.moved(axis, -2.0 * self.correction.get(axis))
                self._mirrored.add(axis)
        return out if out != self.correction else None

    def _undo(
        self,
        failure_class: str,
        entry: ClassRecovery,
        base: Correction,
        directions: Mapping[str, str],
    ) -> Correction:
        """Move against each named direction on the class's axes. The first move is the learnt
        size (else the table's); an axis moved before missed, so the next move is the learnt
        spread (else half the last), in the newly named direction, halved at each later miss."""
        learnt = self.steps.get(failure_class) or self.steps.get(_family(failure_class), Steps())
        out = base
        for verdict_axis, direction in directions.items():
            axis = VERDICT_AXES.get(verdict_axis)
            if axis is None or direction not in ("+", "-"):
                continue
            if axis not in learnt.size and axis not in entry.size:
                continue
            moved = self._steps.setdefault(axis, [])
            if not moved:
                step = learnt.size.get(axis, entry.size.get(axis, 0.0))
            elif len(moved) == 1 and learnt.spread.get(axis):
                step = learnt.spread[axis]
            else:
                step = moved[-1] / 2.0
            moved.append(step)
            out = out.moved(axis, -step if direction == "+" else step)
        return out

    def _start(self, correction: Correction, reason: str) -> Decision:
        self.attempt += 1
        self.correction = correction
        self._alarm_at = None
        self._aborted = None
        self._named = None
        decision = Decision("attempt", self.attempt, 0.0, correction, reason=reason)
        self.decisions.append(decision)
        return decision

    def _stop(self, time: float, reason: str) -> Decision:
        decision = Decision("stop", self.attempt, time, self.correction, reason=reason)
        self.decisions.append(decision)
        return decision


def make_planner(
    policy: PolicyName,
    recovery: RecoveryConfig,
    trained_on: Mapping[str, Any] | None,
    truth: Correction | None = None,
) -> Planner:
    """The planner of one trial, with the steps the verifier learnt per class (its file's
    `trained_on["deviation_by_class"]`); `trained_on` None means no verifier, and introspect
    then runs as retry."""
    if policy == "introspect" and trained_on is None:
        policy = "retry"
    learnt = (trained_on or {}).get("deviation_by_class") or {}
    steps = {
        cls: Steps(
            **{
                part: {VERDICT_AXES[a]: float(v) for a, v in record.get(part, {}).items()}
                for part in ("size", "spread")
            }
        )
        for cls, record in learnt.items()
    }
    return Planner(policy, recovery, steps, truth)

"""One simulated trial under one policy, in-process: the episode's samples feed a
VerifierSession (as verifier_node is fed), its verdicts and the attempts' ends feed the Planner
(as planner_node is fed), and the planner's aborts and corrections drive the episode."""

from __future__ import annotations

from dataclasses import dataclass, field

from rcbht_introspection.plan.planner import Planner, PolicyName, Report, make_planner
from rcbht_introspection.plan.recovery import Correction, RecoveryConfig
from rcbht_introspection.sim.config import SimConfig
from rcbht_introspection.sim.episode import ARM, Attempt, AttemptEnd, Pose, SteppedAttempt, World
from rcbht_introspection.sim.peg_config import PegConfig
from rcbht_introspection.sim.peg_episode import PegAttempt, PegWorld
from rcbht_introspection.sim.tasks import TaskConfig
from rcbht_introspection.verify.model_file import VerifierModel
from rcbht_introspection.verify.monitor import VerifierSession

RATE_HZ = 200.0
"""The simulated snap sensor's rate (the snap cell's, as `rcbht sim`); the peg task's is its
config's."""
TaskWorld = World | PegWorld


def start_attempt(
    config: TaskConfig, world: TaskWorld, correction: Pose, index: int
) -> SteppedAttempt:
    """Attempt `index` of the world under a correction, on its task's simulator."""
    if isinstance(config, PegConfig) and isinstance(world, PegWorld):
        return PegAttempt(config, world, correction, index, config.sensor.rate_hz)
    if isinstance(config, SimConfig) and isinstance(world, World):
        return Attempt(config, world, correction, index, RATE_HZ)
    raise TypeError(f"a {type(world).__name__} cannot run on a {type(config).__name__}")


@dataclass(frozen=True)
class AttemptRecord:
    """One attempt: its correction, how it ended, the physical truth and its times."""

    correction: Correction
    end: AttemptEnd
    alarm_time: float | None
    failure_class: str

    def to_dict(self) -> dict[str, object]:
        e = self.end
        return {
            "correction": {a: round(v, 7) for a, v in self.correction.as_dict().items()},
            "seated": e.seated,
            "reason": e.reason,
            "part_seated": e.latched,
            "duration_s": e.duration,
            "return_s": round(float(e.return_s), 4),
            "alarm_time": self.alarm_time,
            "failure_class": self.failure_class,
        }


@dataclass
class TrialRecord:
    """One trial under one policy: its attempts and the planner's decisions."""

    seed: int
    failure: str
    policy: str
    attempts: list[AttemptRecord] = field(default_factory=list)
    decisions: list[dict[str, object]] = field(default_factory=list)

    @property
    def success(self) -> bool:
        """The part is seated after the last attempt (the physical truth, not the arm's check)."""
        return bool(self.attempts) and self.attempts[-1].end.latched

    @property
    def time_s(self) -> float:
        """All the time the trial took: its attempts, and the returns before each retry."""
        runs = sum(a.end.duration for a in self.attempts)
        return float(runs + sum(a.end.return_s for a in self.attempts[:-1]))

    @property
    def aborts(self) -> int:
        return sum(d["kind"] == "abort" for d in self.decisions)

    def to_dict(self) -> dict[str, object]:
        return {
            "seed": self.seed,
            "class": self.failure or "nominal",
            "outcome": "seated" if self.success else "failed",
            "attempts": len(self.attempts),
            "time_s": round(self.time_s, 4),
            "aborts": self.aborts,
            "attempt_log": [a.to_dict() for a in self.attempts],
            "decisions": self.decisions,
        }


def run_trial(
    config: TaskConfig,
    world: TaskWorld,
    policy: PolicyName,
    recovery: RecoveryConfig,
    verifier: VerifierModel | None,
) -> TrialRecord:
    """The trial's attempts under the policy until the planner stops."""
    trained_on = verifier.trained_on if verifier is not None else None
    planner = make_planner(policy, recovery, trained_on, Correction(*world.truth))
    record = TrialRecord(world.seed, world.failure or "", policy)
    decision = planner.first()
    while decision.kind == "attempt":
        attempt = start_attempt(config, world, decision.correction.values(), decision.attempt - 1)
        session = VerifierSession(verifier) if verifier and planner.reads_verdicts else None
        alarm = _run_attempt(attempt, planner, session)
        assert attempt.end is not None
        record.attempts.append(AttemptRecord(decision.correction, attempt.end, *alarm))
        decision = planner.ended(Report(attempt.end.seated, attempt.end.reason), attempt.time)
    record.decisions = [d.to_dict() for d in planner.decisions]
    return record


def _run_attempt(
    attempt: SteppedAttempt, planner: Planner, session: VerifierSession | None
) -> tuple[float | None, str]:
    """Step the attempt to its end, the verifier judging it until the planner aborts; the
    alarm's time and the class the abort named."""
    alarm: tuple[float | None, str] = (None, "")
    while (sample := attempt.step()) is not None:
        if session is None:
            continue
        for t, name in sample.events:
            session.phase(name, t)
        for v in session.push(ARM, sample.time, sample.wrench):
            decision = planner.verdict(
                v.time, v.alarm, v.failure_class, v.directions, v.class_probabilities
            )
            if decision is not None:
                attempt.abort()
                alarm = (v.alarm_time, decision.failure_class)
                session = None
                break
    return alarm

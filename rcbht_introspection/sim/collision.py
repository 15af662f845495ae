"""Collisions: an external push on the held part during a sub-task, shared by both tasks.

A collision is one or two pulses of force (and the moment of that force about the part's
centre) in a random direction, struck a random delay into a randomly chosen sub-task, as a
person, a tool or the workpiece's surroundings would strike a real arm. Its onset is the first
pulse's start. Whether the task still succeeds is the physics' answer, not the draw's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from rcbht_introspection.sim.arm_config import CollisionConfig
from rcbht_introspection.sim.arm_run import PhaseTrigger, disturbance_record

COLLISION = "collision"
"""The failure family of a struck part (`failures.types` of either task)."""


@dataclass(frozen=True)
class Pulse:
    """One push: its peak force and moment (world frame, N and N m) and duration (s)."""

    force: tuple[float, float, float]
    moment: tuple[float, float, float]
    duration: float
    wait: float
    """Seconds before it starts: into the sub-task (the first), after the pulse before (others)."""


@dataclass(frozen=True)
class Collision:
    """The sub-task a collision strikes in and its pulses."""

    phase: str
    pulses: tuple[Pulse, ...]

    def direction(self) -> dict[str, float]:
        """The first push's direction as a label's `deviation` record: the force's x and y
        share and its moment's yaw share (the signs name where it came from)."""
        f, m = np.asarray(self.pulses[0].force), np.asarray(self.pulses[0].moment)
        norm = float(np.linalg.norm(f)) or 1.0
        yaw = float(m[2] / (np.linalg.norm(m) or 1.0))
        return {
            "x": round(float(f[0]) / norm, 6),
            "y": round(float(f[1]) / norm, 6),
            "yaw": round(yaw, 6),
        }


def draw_collision(
    config: CollisionConfig, phases: Sequence[str], rng: np.random.Generator
) -> Collision:
    """A collision in one of `phases`: one pulse, a second with chance `second_pulse`."""
    phase = phases[int(rng.integers(len(phases)))]
    count = 2 if rng.random() < config.second_pulse else 1
    pulses = []
    for k in range(count):
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction) or 1.0
        force = direction * rng.uniform(*config.force)
        lever = rng.uniform(-config.lever, config.lever, size=3)
        wait = rng.uniform(*(config.delay if k == 0 else config.gap))
        pulses.append(
            Pulse(
                force=_triple(force),
                moment=_triple(np.cross(lever, force)),
                duration=float(rng.uniform(*config.duration)),
                wait=float(wait),
            )
        )
    return Collision(phase, tuple(pulses))


def collision_record(collision: Collision, onset: float, rate_hz: float) -> dict[str, object]:
    """meta.json's failure entry of a collision: its onset (the first pulse's start) on the
    sample clock, and its direction as the deviation record."""
    return disturbance_record(
        COLLISION,
        onset,
        rate_hz,
        "pulse_start",
        deviation=collision.direction(),
        phase=collision.phase,
        pulses=len(collision.pulses),
        duration_s=[round(p.duration, 4) for p in collision.pulses],
        peak_force=round(max(float(np.linalg.norm(p.force)) for p in collision.pulses), 4),
    )


def _triple(v: np.ndarray) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


class CollisionRun:
    """Strikes a collision's pulses on a body as the controller's phases pass: call `update`
    after each physics step with the time reached and the phase running."""

    def __init__(self, collision: Collision, data: mujoco.MjData, body: str) -> None:
        self.collision = collision
        self.data = data
        self.body = data.body(body).id
        self.trigger = PhaseTrigger(collision.phase, collision.pulses[0].wait)
        self.next_start: float | None = None
        self.index = 0
        self.starts: list[float] = []
        """When each pulse started (s): the first is the collision's onset."""

    @property
    def onset(self) -> float | None:
        return self.starts[0] if self.starts else None

    def update(self, t: float, phase: str) -> None:
        """Set the push for the next step (zero outside a pulse)."""
        self.data.xfrc_applied[self.body] = 0.0
        if self.index >= len(self.collision.pulses):
            return
        pulse = self.collision.pulses[self.index]
        if self.next_start is None:  # the first pulse
            self.next_start = self.trigger.update(t, phase)
        if self.next_start is None or t < self.next_start:
            return
        if not self.starts or len(self.starts) <= self.index:
            self.starts.append(t)
        into = t - self.starts[self.index]
        if into >= pulse.duration:
            self.index += 1
            if self.index < len(self.collision.pulses):
                self.next_start = t + self.collision.pulses[self.index].wait
            return
        shape = math.sin(math.pi * into / pulse.duration)
        self.data.xfrc_applied[self.body, :3] = np.asarray(pulse.force) * shape
        self.data.xfrc_applied[self.body, 3:] = np.asarray(pulse.moment) * shape

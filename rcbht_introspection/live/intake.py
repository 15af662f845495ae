"""Sensor intake of segmenter_node: its settings (`IntakeConfig`) and the tare of one arm (`Tare`).

The settings sit under `intake` in config/segmenter.yaml (ROS parameters `intake.<name>`); the
batch commands read the repeated-stamp and frozen-sensor thresholds from the same section
(`load_intake_config`), so a trial gets the same findings read from files and streamed live.
Everything that changes the wrench (tare, tool gravity, spreading stamps) is off by default: the
words then equal the batch engine's.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rcbht_introspection.config_files import config_path, load_config
from rcbht_introspection.config_files import described as _f
from rcbht_introspection.errors import InputError
from rcbht_introspection.io.sensor_checks import RepeatedPolicy


@dataclass(frozen=True)
class IntakeConfig:
    """What segmenter_node does to each wrench sample before the RCBHT (docs/sensor-intake.md)."""

    repeated_stamps: RepeatedPolicy = _f(
        "reject",
        "a sample stamped like the previous one: reject (dropped, counted) or spread (placed "
        "evenly up to the next stamp); a re-sent sample (same values too) is always dropped",
    )
    frozen_samples: int = _f(
        20,
        "frozen sensor: this many consecutive samples with the same six values (0: no check) ...",
    )
    frozen_s: float = _f(0.5, "... spanning at least this many seconds: WARN on /diagnostics")
    tare_at_start: bool = _f(
        False, "subtract the mean of the first tare_window_s seconds of each stream (tare)"
    )
    tare_window_s: float = _f(
        0.5,
        "seconds of samples averaged by a tare (at a stream start, or after a ~/tare request); "
        "their words wait until the tare is measured",
    )
    tool_mass_kg: float = _f(
        0.0, "mass beyond the sensor whose weight is subtracted (0: none; needs pose_topics)"
    )
    tool_com_m: tuple[float, float, float] = _f(
        (0.0, 0.0, 0.0), "centre of mass of that tool in the sensor frame (m)"
    )
    gravity_m_s2: float = _f(9.80665, "gravitational acceleration; the world's z axis points up")

    @property
    def compensates_gravity(self) -> bool:
        return self.tool_mass_kg > 0


def check_intake(cfg: IntakeConfig) -> IntakeConfig:
    """Checks beyond the field types; InputError names the field (relative to `intake`)."""
    checks = (
        (cfg.frozen_samples == 0 or cfg.frozen_samples >= 2, "frozen_samples", "0 or >= 2"),
        (0 <= cfg.frozen_s <= 3600, "frozen_s", "in [0, 3600]"),
        (0 < cfg.tare_window_s <= 10, "tare_window_s", "in (0, 10]"),
        (0 <= cfg.tool_mass_kg <= 1000, "tool_mass_kg", "in [0, 1000]"),
        (all(abs(c) <= 10 for c in cfg.tool_com_m), "tool_com_m", "within 10 m of the sensor"),
        (0 < cfg.gravity_m_s2 <= 30, "gravity_m_s2", "in (0, 30]"),
    )
    for ok, name, rule in checks:
        if not ok:
            raise InputError(f"must be {rule}, got {getattr(cfg, name)}", field=name)
    return cfg


def load_intake_config(path: Path | str | None = None) -> IntakeConfig:
    """The `intake` section of segmenter_node's parameter file (default config/segmenter.yaml)."""
    return load_config(
        IntakeConfig,
        path or config_path("segmenter.yaml"),
        section=("segmenter_node", "ros__parameters", "intake"),
        check=check_intake,
    )


def tare_offsets(rows: Sequence[Sequence[float]] | np.ndarray) -> tuple[float, ...]:
    """The tare of some samples: the mean of each axis."""
    return tuple(np.mean(np.asarray(rows, dtype=np.float64), axis=0).tolist())


def tare_recording(time: np.ndarray, wrench: np.ndarray, window_s: float) -> np.ndarray:
    """A whole recording tared as `Tare` does live: minus the mean of its first `window_s` s."""
    time = np.asarray(time, dtype=np.float64)
    closed = time - time[0] >= window_s  # the comparison Tare.push makes
    n = int(np.argmax(closed)) if closed.any() else len(time)
    wrench = np.asarray(wrench, dtype=np.float64)
    tared: np.ndarray = wrench - np.asarray(tare_offsets(wrench[:n]))
    return tared


class Tare:
    """The bias of one arm's wrench: the mean of the samples of a window, subtracted from then on.

    While a tare is measured its samples are held back; the sample that closes the window
    releases them all, tared. Without a tare the samples pass unchanged.
    """

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self.offsets: tuple[float, ...] | None = None
        self.held: list[tuple[float, Sequence[float]]] = []
        self.measuring = False
        self.completed = 0

    @property
    def idle(self) -> bool:
        """True when samples pass unchanged (no offsets, no tare being measured)."""
        return self.offsets is None and not self.measuring

    def request(self) -> None:
        """Measure a new tare over the next samples (a request during a measurement is a no-op)."""
        self.measuring = True

    def push(self, t: float, values: Sequence[float]) -> list[tuple[float, Sequence[float]]]:
        """One sample in (stream time `t`); the samples to use now, tared (none while measuring)."""
        if not self.measuring:
            return [(t, self.apply(values))]
        if self.held and t - self.held[0][0] >= self.window_s:
            return [*self.release(), (t, self.apply(values))]
        self.held.append((t, values))
        return []

    def release(self) -> list[tuple[float, Sequence[float]]]:
        """End the measurement with the samples held so far (also at the end of a stream); without
        any, the request stays for the next samples."""
        if not self.measuring or not self.held:
            return []
        self.measuring = False
        held, self.held = self.held, []
        self.offsets = tare_offsets([v for _, v in held])
        self.completed += 1
        return [(t, self.apply(v)) for t, v in held]

    def apply(self, values: Sequence[float]) -> Sequence[float]:
        """The sample minus the offsets (unchanged without offsets)."""
        if self.offsets is None:
            return values
        return [v - o for v, o in zip(values, self.offsets, strict=True)]

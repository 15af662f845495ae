"""Force/torque sensor model: tare, bias, drift, white noise, quantization, output rate.

The physics runs at 1/timestep; the sensor averages the physics samples of each output period
(a box anti-alias filter, as a strain-gauge amplifier does) and then adds its own errors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from rcbht_introspection.errors import InputError
from rcbht_introspection.sim.arm_config import Range, SensorConfig


@dataclass(frozen=True)
class SensorDraw:
    """Per-trial sensor errors: constant bias (6,), drift amplitude and period, noise scale."""

    bias: NDArray[np.float64]
    drift: NDArray[np.float64]
    drift_period: float
    drift_phase: float
    noise_scale: float


def draw_sensor(
    config: SensorConfig,
    rng: np.random.Generator,
    bias_force: float,
    bias_torque: float,
    noise_scale: Range,
) -> SensorDraw:
    """One trial's sensor errors: bias (std bias_force / bias_torque), drift amplitude, period and
    phase, and the noise scale (uniform in `noise_scale`)."""
    scale6 = np.array([1.0] * 3 + [0.0] * 3)
    bias = rng.normal(0.0, 1.0, 6) * (scale6 * bias_force + (1 - scale6) * bias_torque)
    drift = rng.normal(0.0, 1.0, 6) * (
        scale6 * config.drift_force + (1 - scale6) * config.drift_torque
    )
    return SensorDraw(
        bias=bias,
        drift=drift,
        drift_period=float(rng.uniform(*config.drift_period)),
        drift_phase=float(rng.uniform(0.0, 2 * math.pi)),
        noise_scale=float(rng.uniform(*noise_scale)),
    )


def decimation(rate_hz: float, timestep: float) -> int:
    """Physics steps per output sample; the rate must divide the physics rate."""
    if rate_hz <= 0:
        raise InputError(f"rate must be positive, got {rate_hz}", field="rate")
    ratio = 1.0 / (timestep * rate_hz)
    k = round(ratio)
    if k < 1 or abs(ratio - k) > 1e-6:
        raise InputError(
            f"rate {rate_hz:g} Hz does not divide the physics rate {1.0 / timestep:g} Hz",
            field="rate",
        )
    return k


def resample(raw: NDArray[np.float64], k: int) -> NDArray[np.float64]:
    """Box-average consecutive blocks of `k` physics samples (drops an incomplete last block)."""
    n = len(raw) // k
    blocks: NDArray[np.float64] = raw[: n * k].reshape(n, k, raw.shape[1]).mean(axis=1)
    return blocks


def measure(
    wrench: NDArray[np.float64],
    time: NDArray[np.float64],
    config: SensorConfig,
    draw: SensorDraw,
    rng: np.random.Generator,
) -> NDArray[np.float64]:
    """Add bias, slow drift, white noise and quantization to a true (tared) wrench (N, 6)."""
    return quantize(_with_errors(wrench, time, config, draw, rng), config)


def sensor_errors(
    time: NDArray[np.float64],
    config: SensorConfig,
    draw: SensorDraw,
    rng: np.random.Generator,
) -> NDArray[np.float64]:
    """The sensor's additive errors alone at the sample times (N, 6), drawn as `measure` draws
    them; causal, so a live attempt reads its samples' errors as a prefix of these."""
    errors: NDArray[np.float64] = _with_errors(np.zeros((len(time), 6)), time, config, draw, rng)
    return errors


def _with_errors(
    wrench: NDArray[np.float64],
    time: NDArray[np.float64],
    config: SensorConfig,
    draw: SensorDraw,
    rng: np.random.Generator,
) -> NDArray[np.float64]:
    """The wrench plus bias, drift, white noise and the two Ornstein-Uhlenbeck disturbances."""
    std = np.array([config.noise_force] * 3 + [config.noise_torque] * 3) * draw.noise_scale
    drift = draw.drift[None, :] * np.sin(
        2 * np.pi * time[:, None] / draw.drift_period + draw.drift_phase
    )
    out: NDArray[np.float64] = (
        wrench + draw.bias[None, :] + drift + rng.normal(0.0, 1.0, wrench.shape) * std[None, :]
    )
    fast = (config.vibration_force, config.vibration_torque, config.vibration_time)
    slow = (config.wander_force, config.wander_torque, config.wander_time)
    for force_std, torque_std, tau in (fast, slow):
        out += ornstein_uhlenbeck(time, force_std, torque_std, tau, draw.noise_scale, rng)
    return out


def quantize(values: NDArray[np.float64], config: SensorConfig) -> NDArray[np.float64]:
    """The sensor's output resolution applied to readings (..., 6)."""
    q = np.array([config.quantization_force] * 3 + [config.quantization_torque] * 3)
    quantized: NDArray[np.float64] = np.round(values / q) * q
    return quantized


def ornstein_uhlenbeck(
    time: NDArray[np.float64],
    force_std: float,
    torque_std: float,
    tau: float,
    scale: float,
    rng: np.random.Generator,
) -> NDArray[np.float64]:
    """Low-frequency disturbance (N, 6): an exact-discretised Ornstein-Uhlenbeck process."""
    # imported here: scipy.signal takes about a second to import, which a process that only
    # dispatches trials to its --jobs workers (commands/sim.py) need not pay
    from scipy.signal import lfilter

    n = len(time)
    if n < 2:
        return np.zeros((n, 6))
    dt = float(time[1] - time[0])
    a = np.exp(-dt / tau)
    std = np.array([force_std] * 3 + [torque_std] * 3) * scale
    kicks = rng.normal(0.0, 1.0, (n, 6)) * std[None, :] * np.sqrt(1.0 - a * a)
    start = rng.normal(0.0, 1.0, 6) * std  # stationary from the first sample
    filtered: tuple[NDArray[np.float64], NDArray[np.float64]] = lfilter(
        [1.0], [1.0, -a], kicks, axis=0, zi=(a * start)[None, :]
    )
    return filtered[0]

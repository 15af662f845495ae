"""The weight of a known tool on the sensor: subtract it, given the sensor's orientation.

Conventions: `rotation` maps sensor-frame vectors to world-frame ones (the orientation of the
sensor in the world, as a pose's quaternion gives it); the world's z axis points up, so gravity
is (0, 0, -g). The sensor measures the tool's weight as a force F = R^T (0, 0, -m g) at the
tool's centre of mass c (sensor frame), i.e. a torque c x F about the sensor origin; both are
subtracted from the measured wrench (Fx, Fy, Fz, Mx, My, Mz).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation


def gravity_wrench(
    rotation: np.ndarray, mass: float, centre_of_mass: Sequence[float], g: float = 9.80665
) -> np.ndarray:
    """The wrench (6,) or (N, 6) the tool's weight puts on the sensor, in the sensor frame."""
    rotation = np.asarray(rotation, dtype=np.float64)
    weight = np.array([0.0, 0.0, -mass * g])
    # R^T w for one (3, 3) or a stack (N, 3, 3) of rotations
    force = np.einsum("...ji,j->...i", rotation, weight)
    torque = np.cross(np.asarray(centre_of_mass, dtype=np.float64), force)
    return np.concatenate([force, torque], axis=-1)


def compensate_gravity(
    wrench: Sequence[float] | np.ndarray,
    rotation: np.ndarray,
    mass: float,
    centre_of_mass: Sequence[float],
    g: float = 9.80665,
) -> np.ndarray:
    """The measured wrench minus the tool's weight (module docstring); (6,) or (N, 6)."""
    weight = gravity_wrench(rotation, mass, centre_of_mass, g)
    compensated: np.ndarray = np.asarray(wrench, dtype=np.float64) - weight
    return compensated


def rotation_from_quaternion(x: float, y: float, z: float, w: float) -> np.ndarray:
    """The (3, 3) rotation of a unit quaternion (geometry_msgs order x, y, z, w; normalised);
    ValueError for a zero or non-finite one (it would turn every compensated sample into NaN)."""
    if not np.all(np.isfinite([x, y, z, w])):
        raise ValueError(f"quaternion ({x}, {y}, {z}, {w}) is not finite")
    matrix: np.ndarray = Rotation.from_quat([x, y, z, w]).as_matrix()
    return matrix

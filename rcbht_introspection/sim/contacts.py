"""Where the held part touches the housing: each contact between a male geom and a housing geom,
named by housing feature (wall top, chamfer, inner face, beam, hook, floor) and side.

A failure's onset is the first contact that the nominal task does not have; this module names the
contacts so that rule can be written down (sim/onset.py) and measured on nominal trials.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco

from rcbht_introspection.sim.arm_model import SIDES
from rcbht_introspection.sim.config import GeometryConfig

Feature = tuple[str, int]
"""(region, side): region is top, chamfer, face, beam, hook or floor; side 0-3 is the housing
side at yaw 0, 90, 180, 270 degrees (+x, +y, -x, -y); the floor is side -1."""
_TOL = 1e-4
"""Tolerance (m) of the region boundaries (contact points lie within the soft-contact margin)."""


@dataclass(frozen=True)
class HousingGeoms:
    """Geom ids of the male part and of each housing feature (kind, side)."""

    male: frozenset[int]
    housing: dict[int, tuple[str, int]]
    """geom id -> (kind: wall, beam, hook or floor; side)."""
    female_body: int


def housing_geoms(model: mujoco.MjModel) -> HousingGeoms:
    """Look up the named geoms of sim/model.py."""
    housing: dict[int, tuple[str, int]] = {model.geom("floor").id: ("floor", -1)}
    for i in range(len(SIDES)):
        for kind, name in (("wall", f"wall{i}_lo"), ("wall", f"wall{i}_hi")):
            housing[model.geom(name).id] = (kind, i)
        housing[model.geom(f"beam{i}").id] = ("beam", i)
        housing[model.geom(f"hook{i}").id] = ("hook", i)
    male = frozenset((model.geom("male_block").id, model.geom("male_neck").id))
    return HousingGeoms(male, housing, model.body("female").id)


def wall_region(geometry: GeometryConfig, radial: float, z: float) -> str:
    """Region of a wall contact from its point in the side's frame (radial = distance from the
    housing axis towards the wall, z = height above the floor): top, chamfer or face."""
    a = geometry.male_half + geometry.clearance
    h = geometry.wall_height
    if z >= h - _TOL and radial >= a + geometry.chamfer - _TOL:
        return "top"
    if z >= h - geometry.chamfer - _TOL and radial >= a - _TOL:
        return "chamfer"
    return "face"


def contact_features(
    geometry: GeometryConfig, geoms: HousingGeoms, data: mujoco.MjData
) -> set[Feature]:
    """The housing features the male part touches now."""
    found: set[Feature] = set()
    ncon = data.ncon
    if ncon == 0:
        return found
    pairs = data.contact.geom[:ncon]
    origin = data.xpos[geoms.female_body]
    rot = data.xmat[geoms.female_body].reshape(3, 3)
    for k in range(ncon):
        g1, g2 = int(pairs[k, 0]), int(pairs[k, 1])
        other = g2 if g1 in geoms.male else g1 if g2 in geoms.male else -1
        hit = geoms.housing.get(other)
        if hit is None:
            continue
        kind, side = hit
        if kind != "wall":
            found.add((kind, side))
            continue
        local = rot.T @ (data.contact.pos[k] - origin)  # housing frame
        ang = math.radians(SIDES[side])
        radial = float(local[0] * math.cos(ang) + local[1] * math.sin(ang))
        found.add((wall_region(geometry, radial, float(local[2])), side))
    return found


def feature_name(feature: Feature) -> str:
    """Readable name of a feature, e.g. `chamfer+x`, `top-y`, `floor`."""
    region, side = feature
    return region if side < 0 else f"{region}{('+x', '+y', '-x', '-y')[side]}"

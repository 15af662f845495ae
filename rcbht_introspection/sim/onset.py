"""Onset of a simulated failure: the first moment its contacts differ from the nominal task's.

Every failure trial has a nominal twin: the same draw (start pose, speeds, friction, sensor)
without the failure's offset. Both runs name the housing features the part touches
(sim/contacts.py) every CONTACT_CHECK seconds; the onset is the first check at which the
failure trial touches a feature its twin does not touch at that moment (a novel contact), or
the twin touches one the failure trial does not (a missing contact: a part that has not landed
where and when the nominal one does). The twin runs only until then; a failure trial that goes
on after its twin ended differs at its next contact. A trial whose contacts never differ has its
onset where the planned stroke ends with the part not seated, if it does, else none.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import mujoco

from rcbht_introspection.sim.config import SimConfig
from rcbht_introspection.sim.contacts import (
    Feature,
    HousingGeoms,
    contact_features,
    feature_name,
    housing_geoms,
)

CONTACT_CHECK = 0.005
"""Seconds between two contact checks (the 200 Hz output grid)."""
NOVEL_CONTACT = "novel_contact"
"""Onset rule: first contact with a housing feature the nominal twin does not touch then."""
MISSING_CONTACT = "missing_contact"
"""Onset rule: first moment the nominal twin touches a feature the failure trial does not."""
STROKE_END = "stroke_end_without_snap"
"""Fallback onset rule: contacts never differed, and the planned stroke ended with the part not
seated (the controller then believes it is done)."""
NO_ONSET = "none"
"""No rule applied: the trial's onset is unknown (null)."""


@dataclass
class ContactLog:
    """Observer of sim.simulate.run_physics: the features touched at every contact check."""

    config: SimConfig
    features: list[frozenset[Feature]] = field(default_factory=list)
    _geoms: HousingGeoms | None = None
    _next: int = 1

    def __call__(self, t: float, phase: str, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        if t + 1e-9 < self._next * CONTACT_CHECK:
            return
        self._next += 1
        if self._geoms is None:
            self._geoms = housing_geoms(model)
        self.features.append(frozenset(contact_features(self.config.geometry, self._geoms, data)))


class Diverged(Exception):
    """Raised by TwinWatch to stop the nominal twin at the failure's onset."""

    def __init__(self, time: float, feature: Feature, rule: str = NOVEL_CONTACT) -> None:
        super().__init__(time, feature, rule)
        self.time = time
        self.feature = feature
        self.rule = rule


@dataclass
class TwinWatch:
    """Observer of the nominal twin: raises Diverged at the first check where the failure trial
    (its ContactLog) touches a feature the twin does not, or the twin one the trial does not."""

    config: SimConfig
    failure: ContactLog
    _geoms: HousingGeoms | None = None
    _check: int = 0

    @property
    def checked(self) -> int:
        """Checks compared so far (the twin's contact checks)."""
        return self._check

    def __call__(self, t: float, phase: str, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        if t + 1e-9 < (self._check + 1) * CONTACT_CHECK:
            return
        if self._geoms is None:
            self._geoms = housing_geoms(model)
        i = self._check
        self._check += 1
        if i >= len(self.failure.features):
            raise Diverged(float("nan"), ("none", -1))  # the failure trial has ended
        twin = contact_features(self.config.geometry, self._geoms, data)
        novel = self.failure.features[i] - twin
        if novel:
            raise Diverged((i + 1) * CONTACT_CHECK, min(novel))
        missing = twin - self.failure.features[i]
        if missing:
            raise Diverged((i + 1) * CONTACT_CHECK, min(missing), MISSING_CONTACT)


@dataclass(frozen=True)
class Onset:
    """A failure's onset: trial time (s, physics grid), the rule that found it, the contact."""

    time: float | None
    rule: str
    contact: str | None = None


def contact_onset(run_twin: Callable[[], object], watch: TwinWatch) -> Onset | None:
    """Run the nominal twin (physics observed by `watch`) up to its divergence; when the twin
    ends first, the failure trial's next contact after that (None: the contacts never differed)."""
    try:
        run_twin()
    except Diverged as d:
        if d.time == d.time:  # not nan
            return Onset(d.time, d.rule, feature_name(d.feature))
        return None  # the failure trial ended first, every check equal
    for i in range(watch.checked, len(watch.failure.features)):
        if watch.failure.features[i]:  # the twin has ended: it touches nothing
            return Onset(
                (i + 1) * CONTACT_CHECK, NOVEL_CONTACT, feature_name(min(watch.failure.features[i]))
            )
    return None

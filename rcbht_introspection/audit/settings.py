"""The audit's settings: its significance level and permutations, and the sensor checks'."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

from rcbht_introspection.audit.changepoint import MIN_SEGMENT
from rcbht_introspection.audit.facts import FREE_MOTION_S
from rcbht_introspection.errors import InputError
from rcbht_introspection.io.sensor_checks import RepeatedPolicy


@dataclass(frozen=True)
class AuditSettings:
    """How strong a change must be to be reported, and how samples are read."""

    alpha: float = 0.01
    """Family-wise error level: of each changepoint test after Bonferroni over the sub-tasks,
    of the session test, and of the outliers after Bonferroni over every duration."""
    permutations: int = 9999
    """Random trial orders of each permutation test (the smallest p-value is 1 / (1 + this))."""
    seed: int = 0
    min_segment: int = MIN_SEGMENT
    """Fewest trials on either side of a change."""
    frozen_samples: int = 20
    frozen_s: float = 0.5
    """A frozen sensor: this many equal samples over at least this long (io/sensor_checks)."""
    classifier: bool = True
    """Run the classifier check of audit/agreement.py beside every change of the durations."""
    repeated: RepeatedPolicy | None = "reject"
    """How a sample stamped like the previous one is read (None: an error, which leaves the
    trial out as unreadable, counted)."""
    period_s: float = 0.0
    """The set's median sample period: the resolution of a duration (taken from the data)."""

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "free_motion_s": FREE_MOTION_S}


def check_settings(settings: AuditSettings) -> None:
    """A one-line error naming the option of a setting that cannot work."""
    if not (0.0 < settings.alpha < 1.0) or not math.isfinite(settings.alpha):
        raise InputError(f"must be between 0 and 1, not {settings.alpha}", field="--alpha")
    if settings.permutations < 1:
        raise InputError(f"must be 1 or more, not {settings.permutations}", field="--permutations")
    if settings.min_segment < 1:
        raise InputError(f"must be 1 or more, not {settings.min_segment}", field="--min-segment")
    if settings.frozen_samples < 0 or settings.frozen_s < 0:
        raise InputError("must not be negative", field="frozen_samples/frozen_s")

"""The verifier's constants in one typed object, loaded from config/verify.yaml."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path

from rcbht_introspection.config_files import config_path, load_config
from rcbht_introspection.errors import InputError
from rcbht_introspection.verify.labels import DIRECTION_AXES

KINDS = ("mean", "std", "change", "change_max", "change_min", "ratio")
"""Feature kinds of an arm (verify/features.py), six axes each."""
WRENCH_AXES = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")
"""The six axes of a wrench, in the order of every kind's columns."""

VERIFY_CONFIG_FILE = "verify.yaml"
CHARACTERISER_HEADS = ("class", *DIRECTION_AXES)
"""The characteriser's heads: the failure class and each deviation axis."""


@dataclass(frozen=True)
class VerifyConfig:
    """Feature, envelope, calibration and characterisation constants (docs/verification.md)."""

    step_s: float = 0.05
    window_s: float = 0.2
    baseline_s: float = 0.1
    elapsed_bin_s: float = 0.1
    elapsed_tolerance_s: float = 0.5
    elapsed_relative: float = 0.25
    neighbours: int = 1
    novelty_features: tuple[str, ...] = ("mean",)
    scale_floor_force: float = 0.02
    scale_floor_torque: float = 0.001
    top_k: int = 3
    false_alarm_rate: float = 0.03
    threshold_segments_s: tuple[float, ...] = ()
    calibration_folds: int = 5
    nominal_fence_iqr: float = 3.0
    """Successes whose largest held-out wrench ratio lies beyond Q3 + this * IQR of all
    successes' (log scale) are left out of the nominal model (0: keep every success)."""
    onset_fraction: float = 0.5
    evidence_s: tuple[float, ...] = (0.1, 0.25, 0.5, 1.0, 2.0, 4.0)
    characteriser_trees: int = 50
    """Trees of each characteriser head's Mondrian forest."""
    contact_weights: dict[str, float] = field(
        default_factory=lambda: {"class": 0.2, "x": 0.2, "y": 0.4}, hash=False
    )
    """Per head, the share of its contact-geometry forest in its probabilities when the part
    touched (a head not named, or 0: its envelope forest alone). Not yaw by default: weighed in
    at 0.3, contact geometry cost the r head up to 9 points on the cell sets."""
    direction_channels: dict[str, tuple[str, ...]] = field(
        default_factory=lambda: {"x": ("Fx", "My"), "r": ("Mz",)}, hash=False
    )
    """Per deviation axis, the wrench axes a second, narrow direction head reads of the
    envelope evidence: a slip in x pushes along x and tips about y; what the controller does
    next shows on every axis and changes with the slip's size (docs/verification.md)."""
    direction_weight: float = 2.0
    """When the class head names a deviation class, the deviation classes of the training
    labels' sign table are scored by the class head's probability times the direction heads'
    probabilities of their signs to this power (times the ramp), and the best is named (0: the
    class head's pick)."""
    direction_ramp_s: float = 4.0
    """The narrow direction heads (`direction_channels`) and `direction_weight` phase in
    linearly over this much evidence since onset: at first the slip's own axes have not moved
    yet, and the heads reading all six name the direction more often."""
    contact_s: float = 0.5
    """Contact geometry is read over the evidence's first contact_s ..."""
    contact_reference_s: float = 0.3
    """... against the mean wrench this long before onset (free motion)."""
    mismatch_min_probability: float = 0.45
    """The mismatch signal (verify/mismatch.py) fires when a final verdict names another
    sub-task than the commanded one with a probability above this."""

    def __post_init__(self) -> None:
        # a copy of its own: configs made by dataclasses.replace do not share one mapping
        object.__setattr__(self, "contact_weights", dict(self.contact_weights))
        object.__setattr__(self, "direction_channels", dict(self.direction_channels))


def check_verify_config(cfg: VerifyConfig) -> None:
    """Ranges beyond the field types (the loader adds file and line to the error)."""
    for name in (
        "step_s",
        "window_s",
        "baseline_s",
        "elapsed_bin_s",
        "scale_floor_force",
        "scale_floor_torque",
    ):
        if getattr(cfg, name) <= 0:
            raise InputError(f"must be > 0, got {getattr(cfg, name)}", field=name)
    if cfg.elapsed_tolerance_s < 0:
        raise InputError(
            f"must be >= 0, got {cfg.elapsed_tolerance_s}", field="elapsed_tolerance_s"
        )
    if cfg.elapsed_relative < 0:
        raise InputError(f"must be >= 0, got {cfg.elapsed_relative}", field="elapsed_relative")
    if cfg.neighbours < 1:
        raise InputError(f"must be >= 1, got {cfg.neighbours}", field="neighbours")
    for i, k in enumerate(cfg.novelty_features):
        if k not in KINDS:
            raise InputError(
                f"unknown feature kind {k!r} (known: {', '.join(KINDS)})",
                field=f"novelty_features[{i}]",
            )
    if not cfg.novelty_features:
        raise InputError("needs at least one feature kind", field="novelty_features")
    if cfg.characteriser_trees < 1:
        raise InputError(
            f"must be >= 1, got {cfg.characteriser_trees}", field="characteriser_trees"
        )
    if cfg.top_k < 1:
        raise InputError(f"must be >= 1, got {cfg.top_k}", field="top_k")
    if not 0 < cfg.false_alarm_rate < 1:
        raise InputError(f"must be in (0, 1), got {cfg.false_alarm_rate}", field="false_alarm_rate")
    seg = cfg.threshold_segments_s
    if any(b <= a for a, b in itertools.pairwise(seg)) or any(x <= 0 for x in seg):
        raise InputError(
            f"must be positive and increasing, got {list(seg)}", field="threshold_segments_s"
        )
    if cfg.calibration_folds < 2:
        raise InputError(f"must be >= 2, got {cfg.calibration_folds}", field="calibration_folds")
    if cfg.nominal_fence_iqr < 0:
        raise InputError(f"must be >= 0, got {cfg.nominal_fence_iqr}", field="nominal_fence_iqr")
    if not 0 <= cfg.onset_fraction < 1:
        raise InputError(f"must be in [0, 1), got {cfg.onset_fraction}", field="onset_fraction")
    if not cfg.evidence_s or any(e <= 0 for e in cfg.evidence_s):
        raise InputError("needs at least one span, all > 0", field="evidence_s")
    for head, weight in cfg.contact_weights.items():
        if head not in CHARACTERISER_HEADS:
            raise InputError(
                f"unknown head {head!r} (known: {', '.join(CHARACTERISER_HEADS)})",
                field=f"contact_weights.{head}",
            )
        if not 0 <= weight <= 1:  # NaN too
            raise InputError(f"must be in [0, 1], got {weight}", field=f"contact_weights.{head}")
    for axis, channels in cfg.direction_channels.items():
        if axis not in DIRECTION_AXES:
            raise InputError(
                f"unknown deviation axis {axis!r} (known: {', '.join(DIRECTION_AXES)})",
                field=f"direction_channels.{axis}",
            )
        if not channels:
            raise InputError("needs at least one wrench axis", field=f"direction_channels.{axis}")
        for i, c in enumerate(channels):
            if c not in WRENCH_AXES:
                raise InputError(
                    f"unknown wrench axis {c!r} (known: {', '.join(WRENCH_AXES)})",
                    field=f"direction_channels.{axis}[{i}]",
                )
    if not 0 <= cfg.direction_weight < math.inf:  # NaN too
        raise InputError(
            f"must be >= 0 and finite, got {cfg.direction_weight}", field="direction_weight"
        )
    for name in ("contact_s", "contact_reference_s", "direction_ramp_s"):
        if not getattr(cfg, name) > 0:  # NaN too
            raise InputError(f"must be > 0, got {getattr(cfg, name)}", field=name)
    if not 0 < cfg.mismatch_min_probability < 1:
        raise InputError(
            f"must be in (0, 1), got {cfg.mismatch_min_probability}",
            field="mismatch_min_probability",
        )


def load_verify_config(path: Path | str | None = None) -> VerifyConfig:
    """The verify section of config/verify.yaml (or of `path`)."""
    file = Path(path) if path is not None else config_path(VERIFY_CONFIG_FILE)
    return load_config(VerifyConfig, file, section=("verify",), check=check_verify_config)

"""The verifier's settings in one typed object, loaded from config/verify.yaml."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from rcbht_introspection.config_files import config_path, load_config
from rcbht_introspection.errors import InputError

WRENCH_AXES = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")
"""The six axes of a wrench, in the order of every feature block's columns."""

VERIFY_CONFIG_FILE = "verify.yaml"


@dataclass(frozen=True)
class VerifyConfig:
    """Detection, calibration and characterisation settings (docs/verification.md)."""

    step_s: float = 0.05
    """The verifier judges every step_s of stream time."""
    window_s: float = 0.2
    """Each tick reads the mean wrench over the last window_s."""
    lag_s: float = 0.75
    """The detector reads how that mean changed over the last lag_s: a constant sensor bias,
    drift slower than lag_s and the gripper's load cancel."""
    elapsed_tolerance_s: float = 0.5
    """A tick is compared with the successes' ticks this close in time into the sub-task."""
    false_alarm_rate: float = 0.03
    """Target share of nominal runs with an alarm (conformal, over held-out successes)."""
    calibration_folds: int = 5
    """Cross-fitting folds over the successes (grouped by session where labels name one)."""
    onset_fraction: float = 0.5
    """Onset estimate: the first tick of the excursion above this share of the threshold."""
    evidence_s: tuple[float, ...] = (0.1, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0)
    """The characteriser summarises the evidence over these spans after onset and names the
    class again as each span closes."""
    mismatch_min_probability: float = 0.45
    """The mismatch signal fires when a final verdict names another sub-task than the
    commanded one with a probability above this (needs the classifier's beliefs)."""
    signals: tuple[str, ...] = ("wrench", "timing")
    """The detector's signals: `wrench` and `timing`; `transient` for sudden contacts (it alarms
    on a push within a tick or two, at the cost of later alarms on slow deviations) and
    `departure` for slow ones (a slip that grows for seconds)."""


VERIFIER_SIGNALS = ("wrench", "transient", "departure", "timing")
"""The signals the verifier's detector can read (verify/detector.py)."""


def check_verify_config(cfg: VerifyConfig) -> None:
    """Ranges beyond the field types (the loader adds file and line to the error)."""
    for name in ("step_s", "window_s", "lag_s"):
        if not getattr(cfg, name) > 0:  # NaN too
            raise InputError(f"must be > 0, got {getattr(cfg, name)}", field=name)
    if not cfg.elapsed_tolerance_s >= 0:
        raise InputError(
            f"must be >= 0, got {cfg.elapsed_tolerance_s}", field="elapsed_tolerance_s"
        )
    unknown = [s for s in cfg.signals if s not in VERIFIER_SIGNALS]
    if unknown or not cfg.signals or len(set(cfg.signals)) != len(cfg.signals):
        known = ", ".join(VERIFIER_SIGNALS)
        raise InputError(f"must be distinct signals of {known}, got {cfg.signals}", field="signals")
    if not 0 < cfg.false_alarm_rate < 1:
        raise InputError(f"must be in (0, 1), got {cfg.false_alarm_rate}", field="false_alarm_rate")
    if cfg.calibration_folds < 2:
        raise InputError(f"must be >= 2, got {cfg.calibration_folds}", field="calibration_folds")
    if not 0 <= cfg.onset_fraction < 1:
        raise InputError(f"must be in [0, 1), got {cfg.onset_fraction}", field="onset_fraction")
    spans = cfg.evidence_s
    if not spans or any(not e > 0 for e in spans) or list(spans) != sorted(set(spans)):
        raise InputError("needs at least one span, all > 0 and increasing", field="evidence_s")
    if not 0 < cfg.mismatch_min_probability < 1:
        raise InputError(
            f"must be in (0, 1), got {cfg.mismatch_min_probability}",
            field="mismatch_min_probability",
        )


def load_verify_config(path: Path | str | None = None) -> VerifyConfig:
    """The verify section of config/verify.yaml (or of `path`)."""
    file = Path(path) if path is not None else config_path(VERIFY_CONFIG_FILE)
    return load_config(VerifyConfig, file, section=("verify",), check=check_verify_config)

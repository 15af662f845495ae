"""Every threshold and filter constant of the RCBHT in one typed object, loaded from config/rcbht.yaml.

The `reference` profile reproduces the v2.0.2 (a1ca1d1) code that produced the published label
files, including its [bug]-tagged behaviours (spec 2.1-2.5); other profiles may override fields.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rcbht_introspection.config_files import (
    config_from_document,
    config_path,
    load_profile,
    only_profile,
    to_mapping,
    write_profile,
)
from rcbht_introspection.errors import InputError
from rcbht_introspection.taxonomy.words import AXES

CONFIG_FILE = "rcbht.yaml"


@dataclass(frozen=True)
class TaxonomyConfig:
    """RCBHT constants; names follow the spec (sections 2.1-2.5)."""

    profile: str = "reference"
    # 2.1 segmentation
    window: int = 5
    """W: the growing window advances W samples per fit."""
    fit_threshold: float = 0.90
    """A window still "fits" while R^2 > fit_threshold."""
    fit_zero_sum: float = 1e-4
    """SSres or SStot below this count as 0 (then R^2 is 1)."""
    fit_noise_floor: dict[str, float] | None = None
    """Per-axis residual variance per sample that still counts as a fit (a sensor's noise,
    from `rcbht calibrate`): a window also fits while SSres <= n * floor. None = R^2 only."""
    # 2.1 gradient classification: [pimp bpos mpos spos sneg mneg bneg nimp]
    gradient_thresholds: tuple[float, ...] = (70.0, 46.0, 23.0, 1.0, -1.0, -23.0, -46.0, -70.0)
    calibrated_thresholds: dict[str, tuple[float, ...]] | None = None
    """Per-axis 8-value spectra from the calibration routine; None = the defaults above."""
    domain_axes: tuple[str, ...] = ("Mx", "My", "Mz")
    """Axes whose thresholds shrink when the signal's domain is small."""
    domain_threshold: float = 1.9
    domain_divisor: float = 10.0
    domain_rank: int = 4
    """Domain = |top_margin * rank-th largest| + |bottom_margin * rank-th smallest| sample."""
    domain_top_margin: float = 1.02
    domain_bottom_margin: float = 0.98
    # 2.1 primitive clean-up (and two switches of later code states)
    primitive_cleanup: bool = True
    """Run primitivesCleanUp.m (False: the primitives go to the MC layer as segmented)."""
    final_segment: bool = True
    """Keep the wrap-up segment wStart..N (False: the later code state that drops it)."""
    primitive_amplitude_ratio: float = 2.0
    primitive_length_ratio: float = 5.0
    # 2.2 MC layer
    composition_amplitude_ratio: float = 2.0
    composition_length_ratio: float = 5.0
    # 2.3 MC filtering
    composition_cleanup_cycles: int = 4
    adjustment_similarity: float = 0.5
    adjustment_mating_guard: bool = True
    """a1ca1d1: repeated 'a' chains merge only while the next MC ends before mating - 0.002 s."""
    adjustment_time_offset: float = 0.002
    adjustment_time_step: float = 0.001
    duration_amplitude_ratio: float = 5.0
    duration_ratio: float = 5.0
    duration_gate_breaks: bool = True
    """a1ca1d1: a failed amplitude gate stops the duration pass (HEAD skips the pair instead)."""
    contact_amplitude_fraction: float = 0.1
    adjustment_merge_similarity: tuple[float, float] = (0.5, 0.5)
    """(amplitude, avgVal) similarity widths for merging a/i/d pairs into 'a'."""
    constant_merge_similarity: tuple[float, float] = (1.5, 1.0)
    """(amplitude, avgVal) similarity widths for merging i/d/k pairs into 'k'."""
    # 2.4 LLB layer
    behavior_time_threshold: float = 0.10
    # 2.5 LLB refinement
    behavior_refinement_cycles: int = 5
    behavior_amplitude_ratio: float = 5.0
    behavior_duration_ratio: float = 5.0
    push_pull_similarity: tuple[float, float] = (1.5, 1.0)
    align_push_similarity: tuple[float, float] = (0.5, 1.0)
    fixed_similarity: tuple[float, float] = (0.75, 0.75)

    def thresholds(self, axis: str) -> tuple[float, ...]:
        """The 8-value gradient spectrum of one axis before the domain rule."""
        if self.calibrated_thresholds and axis in self.calibrated_thresholds:
            return self.calibrated_thresholds[axis]
        return self.gradient_thresholds


def _check(config: TaxonomyConfig) -> None:
    """Checks beyond the field types (the loader adds file, line and profile to the error)."""
    if len(config.gradient_thresholds) != 8:
        raise InputError(
            f"expected 8 values, got {len(config.gradient_thresholds)}",
            field="gradient_thresholds",
        )
    for axis, values in (config.calibrated_thresholds or {}).items():
        if axis not in AXES:
            raise InputError(
                f"unknown axis (known: {', '.join(AXES)})", field=f"calibrated_thresholds.{axis}"
            )
        if len(values) != 8:
            raise InputError(
                f"expected 8 values, got {len(values)}", field=f"calibrated_thresholds.{axis}"
            )
    for axis, floor in (config.fit_noise_floor or {}).items():
        if axis not in AXES:
            raise InputError(
                f"unknown axis (known: {', '.join(AXES)})", field=f"fit_noise_floor.{axis}"
            )
        if not floor >= 0:
            raise InputError(f"must be >= 0, got {floor}", field=f"fit_noise_floor.{axis}")
    if config.window < 1:
        raise InputError(f"must be >= 1, got {config.window}", field="window")


def load_taxonomy_config(
    profile: str | None = "reference", path: Path | str | None = None
) -> TaxonomyConfig:
    """Load one profile of config/rcbht.yaml (`profiles: {name: {field: value}}`) over the defaults.

    With `path` (e.g. a file written by `rcbht calibrate`), profile None means its only profile.
    """
    file = Path(path) if path is not None else config_path(CONFIG_FILE)
    if profile is None:
        profile = only_profile(file, kind="taxonomy") if path is not None else "reference"
    return load_profile(
        TaxonomyConfig, file, profile, kind="taxonomy", fixed={"profile": profile}, check=_check
    )


def write_taxonomy_config(config: TaxonomyConfig, path: Path | str, header: str = "") -> Path:
    """Write `config` as the one profile of a YAML file (config/rcbht.yaml's form), named by
    config.profile; load_taxonomy_config reads it back equal."""
    return write_profile(path, config.profile, config, omit=("profile",), header=header)


def taxonomy_values(config: TaxonomyConfig) -> dict[str, Any]:
    """The profile's values (not its name) as plain data: what taxonomy_digest hashes and a
    model file embeds."""
    return {k: v for k, v in to_mapping(config).items() if k != "profile"}


def taxonomy_from_document(
    document: Any, profile: str, *, path: Path | str, section: Sequence[str] = ()
) -> TaxonomyConfig:
    """Profile `profile` from the values at `section` of plain data (e.g. a model file's header),
    checked as a profile of config/rcbht.yaml is: a bad value is a one-line InputError."""
    return config_from_document(
        TaxonomyConfig,
        document,
        path=path,
        section=section,
        fixed={"profile": profile},
        check=_check,
    )


def taxonomy_digest(config: TaxonomyConfig) -> str:
    """SHA-256 of the profile's values (not its name): equal digests label alike."""
    values = taxonomy_values(config)
    return hashlib.sha256(json.dumps(values, sort_keys=True).encode()).hexdigest()


def is_reference(config: TaxonomyConfig) -> bool:
    """True when `config` has the reference profile's values (the golden files' words)."""
    return taxonomy_digest(config) == taxonomy_digest(default_config())


_DEFAULT: TaxonomyConfig | None = None


def default_config() -> TaxonomyConfig:
    """The `reference` profile from config/rcbht.yaml (loaded once)."""
    global _DEFAULT
    if _DEFAULT is None:
        _DEFAULT = load_taxonomy_config("reference")
    return _DEFAULT

"""A taxonomy profile for a new sensor and rate, measured on its own trials (`rcbht calibrate`).

The reference constants fit HIRO's smooth 200 Hz signals. On a noisy sensor nearly every window
fails the R^2 test (R^2 of noise is near 0 whatever the threshold), so a primitive is cut at
every window and every gradient is noise. The calibration measures, over all inputs:

* the window: the reference's 25 ms at the input's sample rate, never fewer than its 5 samples;
* a per-axis noise floor: the median residual variance of a line fitted to runs of 2W+1 samples,
  times the smallest factor that brings the axis's primitives per window to MAX_CUT_FRACTION
  (0 when the axis is already there, as on HIRO, so the original R^2 test alone decides);
* per-axis gradient spectra (spec 2.1's computeGradientSpectrum) from the segments' gradients:
  near-constant = the CONST_QUANTILE of the axis's |gradient|, largest = the IMPULSE_QUANTILE of
  the |gradient| of its group (forces or moments share one impulse scale, as the spec's
  calibration shares Fz's and My's);
* the moment-axis domain rule is off: it adapts the default spectrum to small moment signals,
  and a measured spectrum already has each axis's own scale.

A group (forces, moments) that the base profile already fits keeps the base's spectra and domain
rule: its segmentation is the base's (same window, no noise floor) and the base labels CONS_BAND
of its primitives 'cons' on every axis. So a sensor like the base's gets the base's words.

docs/taxonomy.md ("Calibrating for a new sensor") explains the rules and the table.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from rcbht_introspection.taxonomy.batch import label_trial
from rcbht_introspection.taxonomy.config import TaxonomyConfig, default_config
from rcbht_introspection.taxonomy.primitives import (
    GRAD,
    axis_domain,
    gradient_spectrum,
    segment_arrays,
)
from rcbht_introspection.taxonomy.stream import TrialLike
from rcbht_introspection.taxonomy.words import AXES, LEVELS, Level, TrialWords, Word

REFERENCE_RATE_HZ = 200.0
"""HIRO's sample rate, at which the reference window (W = 5) spans 25 ms."""
MAX_CUT_FRACTION = 0.5
"""Primitives per window an axis may have. HIRO with the reference profile: 0.075-0.39 per axis
over the REAL set, 0.39-0.58 over the SIM set (a noisy sensor: 0.9-1.0)."""
FLOOR_FACTORS: tuple[float, ...] = (0.0, *(0.25 * 2 ** (k / 4) for k in range(25)))
"""Noise-floor factors tried, smallest first: 0 (the R^2 test alone), then 0.25 .. 16 in steps
of 2^(1/4)."""
CONST_QUANTILE = 0.55
"""Near-constant gradient: this quantile of a group's |gradient|. REAL HIRO with the reference
profile labels 56 % of all primitives 'cons' (41-68 % per axis)."""
IMPULSE_QUANTILE = 0.997
"""Largest (impulse) gradient: this quantile of a group's |gradient| (REAL HIRO: pimp = 70 lies
at the 0.991-0.997 quantiles of Fx and Fz)."""
AXIS_GROUPS: tuple[tuple[str, ...], ...] = (("Fx", "Fy", "Fz"), ("Mx", "My", "Mz"))
"""Axes that share one spectrum, as the default profile's force and moment axes do."""
CONS_BAND = (0.35, 0.75)
"""A base spectrum fits a group whose primitives it labels 'cons' in this share on every axis
(REAL HIRO under the reference: 0.41-0.68 per axis); such a group keeps it."""

Series = tuple[np.ndarray, np.ndarray]
"""(N,) time and (N, 6) wrench of one arm of one trial."""


@dataclass(frozen=True)
class ProfileStats:
    """How a profile segments and labels a set of trials (one side of the before/after table)."""

    profile: str
    window: int
    primitives_per_window: dict[str, float]
    """Per axis: primitives (segments before clean-up) / window steps."""
    const_share: dict[str, float]
    """Per axis: share of the primitives labelled 'cons'."""
    words_per_second: dict[str, float]
    """Per level and 'all': words of every axis and arm per second of data."""


@dataclass(frozen=True)
class Calibration:
    """A calibrated profile and what it was measured from."""

    config: TaxonomyConfig
    rate_hz: float
    noise_variance: dict[str, float]
    """Per axis: median residual variance per sample of a line over 2W+1 samples."""
    floor_factor: dict[str, float]
    """Per axis: the factor chosen from FLOOR_FACTORS (0 = no floor)."""
    limits: dict[str, tuple[float, float]]
    """Per axis: (largest, near-constant) gradient, the spectrum's pimp and spos."""
    domains: dict[str, float]
    """Per axis: median domain (adjustAxes.m) over the inputs, for the report."""
    notes: list[str] = field(default_factory=list)
    """What could not be fitted, one line each: axes kept at the base profile's thresholds, axes
    still above MAX_CUT_FRACTION."""


def trial_series(trials: Sequence[TrialLike]) -> list[Series]:
    """Every arm of every trial as one (time, wrench) series."""
    return [
        (np.asarray(t.time, dtype=np.float64), np.asarray(t.wrench[arm], dtype=np.float64))
        for t in trials
        for arm in t.arms
        if len(t.time) > 1
    ]


def sample_rate(series: Sequence[Series]) -> float:
    """Median sample rate (Hz) over all series (the median step of each, then their median)."""
    steps = [float(np.median(np.diff(t))) for t, _ in series]
    return 1.0 / float(np.median(steps))


def calibrated_window(rate_hz: float, base: TaxonomyConfig) -> int:
    """The base window's time span at `rate_hz`, never fewer samples than the base window."""
    return max(base.window, round(base.window * rate_hz / REFERENCE_RATE_HZ))


def residual_variance(series: Sequence[Series], window: int) -> dict[str, float]:
    """Per axis: median over runs of 2W+1 samples of SSres / n of a least-squares line."""
    n = 2 * window + 1
    per_axis: list[np.ndarray] = []
    for t, y in series:
        k = len(t) // n
        if k == 0:
            continue
        tb = t[: k * n].reshape(k, n)
        yb = y[: k * n].reshape(k, n, -1)
        tc = tb - tb.mean(axis=1, keepdims=True)
        yc = yb - yb.mean(axis=1, keepdims=True)
        stt = (tc * tc).sum(axis=1)[:, None]
        sty = (tc[:, :, None] * yc).sum(axis=1)
        syy = (yc * yc).sum(axis=1)
        per_axis.append(np.maximum(syy - sty * sty / stt, 0.0) / n)
    if not per_axis:
        return dict.fromkeys(AXES, 0.0)
    values = np.concatenate(per_axis)
    return {axis: _median_finite(values[:, a]) for a, axis in enumerate(AXES)}


def _median_finite(values: np.ndarray) -> float:
    """Median of the finite values (a bag may carry NaN samples; 0 when none is finite)."""
    finite = values[np.isfinite(values)]
    return float(np.median(finite)) if len(finite) else 0.0


def _segments(series: Sequence[Series], config: TaxonomyConfig) -> list[list[list[float]]]:
    """Per axis: the segments of every series ([avg, max, min, start, finish, gradient])."""
    out: list[list[list[float]]] = [[] for _ in AXES]
    for t, y in series:
        seg = segment_arrays(t, y, config)
        for a in range(len(AXES)):
            out[a].extend(seg.segments[a])
    return out


def cut_fractions(series: Sequence[Series], config: TaxonomyConfig) -> dict[str, float]:
    """Per axis: segments / window steps over all series (the primitives-per-window figure)."""
    windows = sum((len(t) - 1) / config.window for t, _ in series)
    segs = _segments(series, config)
    return {axis: len(segs[a]) / windows if windows else 0.0 for a, axis in enumerate(AXES)}


def choose_noise_floor(
    series: Sequence[Series], config: TaxonomyConfig, variance: dict[str, float]
) -> dict[str, float]:
    """Per axis: the smallest FLOOR_FACTORS entry whose primitives per window is at most
    MAX_CUT_FRACTION (the largest if none is)."""
    chosen: dict[str, float] = {}
    for factor in FLOOR_FACTORS:
        floors = {axis: factor * v for axis, v in variance.items()}
        trial = dataclasses.replace(config, fit_noise_floor=floors if factor else None)
        fractions = cut_fractions(series, trial)
        for axis in AXES:
            if axis not in chosen and fractions[axis] <= MAX_CUT_FRACTION:
                chosen[axis] = factor
        if len(chosen) == len(AXES):
            break
    return {axis: chosen.get(axis, FLOOR_FACTORS[-1]) for axis in AXES}


def gradient_limits(gradients: dict[str, np.ndarray]) -> dict[str, tuple[float, float]]:
    """Per axis: (largest, near-constant) gradient, the IMPULSE and CONST quantiles of the
    |gradient| of its group's axes pooled (AXIS_GROUPS)."""
    limits: dict[str, tuple[float, float]] = {}
    for group in AXIS_GROUPS:
        parts = [np.abs(gradients[a]) for a in group if a in gradients]
        pooled = np.concatenate(parts) if parts else np.empty(0)
        pooled = pooled[np.isfinite(pooled)]
        pimp, pconst = (
            (
                float(np.quantile(pooled, IMPULSE_QUANTILE)),
                float(np.quantile(pooled, CONST_QUANTILE)),
            )
            if len(pooled)
            else (0.0, 0.0)
        )
        for axis in group:
            limits[axis] = (pimp, pconst)
    return limits


def _short(value: float) -> float:
    """`value` to 4 significant digits: a readable profile file, far finer than the data."""
    return float(f"{value:.4g}")


def calibrate_profile(
    trials: Sequence[TrialLike], name: str = "calibrated", base: TaxonomyConfig | None = None
) -> Calibration:
    """Measure a profile named `name` on `trials`: `base` (default: reference) with the window,
    noise floors, gradient spectra and domain rule fitted to them (module docstring)."""
    base = base or default_config()
    series = trial_series(trials)
    rate = sample_rate(series)
    window = calibrated_window(rate, base)
    config = dataclasses.replace(base, profile=name, window=window, fit_noise_floor=None)
    variance = residual_variance(series, window)
    factors = choose_noise_floor(series, config, variance)
    floors = {axis: _short(factors[axis] * variance[axis]) for axis in AXES if factors[axis]}
    config = dataclasses.replace(config, fit_noise_floor=floors or None)
    segs = _segments(series, config)
    windows = sum((len(t) - 1) / window for t, _ in series)
    notes: list[str] = []
    for a, axis in enumerate(AXES):
        if windows and len(segs[a]) / windows > MAX_CUT_FRACTION:
            notes.append(
                f"{axis}: {len(segs[a]) / windows:.3f} primitives per window even with the "
                f"largest noise floor ({factors[axis]:g} x the residual variance)"
            )
    gradients = {
        axis: np.array([s[GRAD] for s in segs[a]], dtype=np.float64) for a, axis in enumerate(AXES)
    }
    limits = gradient_limits(gradients)
    spectra: dict[str, tuple[float, ...]] = {}
    for axis in AXES:
        pimp, pconst = limits[axis]
        if 0.0 < pconst < pimp:
            spectra[axis] = tuple(_short(v) for v in gradient_spectrum(pimp, pconst))
        else:
            spectra[axis] = base.thresholds(axis)
            notes.append(
                f"{axis}: gradients give no spectrum (largest {pimp:.3g}, near-constant "
                f"{pconst:.3g}); the base profile's thresholds are kept"
            )
    kept = _groups_the_base_fits(trials, base, window, factors)
    for axis in kept:
        del spectra[axis]
    config = dataclasses.replace(
        config,
        calibrated_thresholds=spectra or None,
        domain_axes=tuple(a for a in base.domain_axes if a in kept),
    )
    if kept:
        notes.append(f"{', '.join(kept)}: the base profile fits; its spectra and domain rule kept")
    domains = {
        axis: _median_finite(np.array([axis_domain(y[:, a], base) for _, y in series]))
        for a, axis in enumerate(AXES)
    }
    return Calibration(config, rate, variance, factors, limits, domains, notes)


def _groups_the_base_fits(
    trials: Sequence[TrialLike],
    base: TaxonomyConfig,
    window: int,
    factors: dict[str, float],
) -> tuple[str, ...]:
    """Axes of the groups whose segmentation is the base's and whose 'cons' share under the base
    lies in CONS_BAND on every axis (they keep the base's spectra)."""
    if window != base.window:
        return ()
    same = [g for g in AXIS_GROUPS if not any(factors[axis] for axis in g)]
    if not same:
        return ()
    shares = profile_stats(trials, base).const_share
    low, high = CONS_BAND
    return tuple(a for g in same if all(low <= shares[a] <= high for a in g) for a in g)


@dataclass(frozen=True)
class Comparison:
    """The before/after table: two profiles on the same trials, and how often they agree."""

    before: ProfileStats
    after: ProfileStats
    agreement: dict[str, float]
    """Per level: share of (sample, axis, arm) points where both profiles give the same label."""


def labels_at(words: Sequence[Word], times: np.ndarray) -> np.ndarray:
    """The label of the word covering each time ('' where none does; the later word at a
    shared boundary)."""
    out = np.full(len(times), "", dtype=object)
    if not words:
        return out
    starts = np.array([w.start for w in words])
    ends = np.array([w.end for w in words])
    labels = np.array([w.label for w in words], dtype=object)
    idx = np.searchsorted(starts, times, side="right") - 1
    inside = (idx >= 0) & (times <= ends[np.clip(idx, 0, None)])
    out[inside] = labels[idx[inside]]
    return out


class _Tally:
    """Running counts of one profile's words over trials (ProfileStats in the end)."""

    def __init__(self, config: TaxonomyConfig) -> None:
        self.config = config
        self.windows = 0.0
        self.seconds = 0.0
        self.primitives = dict.fromkeys(AXES, 0)
        self.const = dict.fromkeys(AXES, 0)
        self.words = dict.fromkeys((level.value for level in LEVELS), 0)

    def add(self, trial: TrialLike, labelled: TrialWords) -> None:
        for arm in trial.arms:
            self.windows += (len(trial.time) - 1) / self.config.window
            self.seconds += float(trial.time[-1] - trial.time[0])
            for axis in AXES:
                prims = labelled.axis_words(arm, Level.PRIMITIVE, axis)
                self.primitives[axis] += len(prims)
                self.const[axis] += sum(p.label == "cons" for p in prims)
                for level in LEVELS:
                    self.words[level.value] += len(labelled.axis_words(arm, level, axis))

    def stats(self) -> ProfileStats:
        def ratio(a: float, b: float) -> float:
            return a / b if b else 0.0

        rates = {level: ratio(n, self.seconds) for level, n in self.words.items()}
        rates["all"] = ratio(sum(self.words.values()), self.seconds)
        return ProfileStats(
            self.config.profile,
            self.config.window,
            {a: ratio(self.primitives[a], self.windows) for a in AXES},
            {a: ratio(self.const[a], self.primitives[a]) for a in AXES},
            rates,
        )


def profile_stats(trials: Sequence[TrialLike], config: TaxonomyConfig) -> ProfileStats:
    """Primitives per window, 'cons' share per axis and words per second of `config` on `trials`."""
    tally = _Tally(config)
    for trial in trials:
        if len(trial.time) > 1:
            tally.add(trial, label_trial(trial, config))
    return tally.stats()


def compare_profiles(
    trials: Sequence[TrialLike], before: TaxonomyConfig, after: TaxonomyConfig
) -> Comparison:
    """Both profiles' ProfileStats on `trials`, and their label agreement at every sample."""
    tallies = (_Tally(before), _Tally(after))
    same = dict.fromkeys((level.value for level in LEVELS), 0)
    points = 0
    for trial in trials:
        if len(trial.time) < 2:
            continue
        labelled = [label_trial(trial, config) for config in (before, after)]
        for tally, words in zip(tallies, labelled, strict=True):
            tally.add(trial, words)
        times = np.asarray(trial.time, dtype=np.float64)
        for arm in trial.arms:
            points += len(times) * len(AXES)
            for level in LEVELS:
                for axis in AXES:
                    a, b = (labels_at(w.axis_words(arm, level, axis), times) for w in labelled)
                    same[level.value] += int((a == b).sum())
    agreement = {level: n / points if points else 0.0 for level, n in same.items()}
    return Comparison(tallies[0].stats(), tallies[1].stats(), agreement)


__all__ = [
    "Calibration",
    "Comparison",
    "ProfileStats",
    "TrialLike",
    "calibrate_profile",
    "calibrated_window",
    "choose_noise_floor",
    "compare_profiles",
    "cut_fractions",
    "gradient_limits",
    "labels_at",
    "profile_stats",
    "residual_variance",
    "sample_rate",
    "trial_series",
]

"""Changes of the free-motion wrench level within a session, in the order of the inputs.

The sessions of audit/sessions.py are groups far apart against the trial-to-trial spread. A
smaller shift (a re-bias of a few sigmas, a sensor warming up) overlaps that spread and forms no
group, but shows in the order the trials were recorded. Within each session of at least
2 x min_segment trials, the levels in input order are scanned as one multichannel sequence
(audit/changepoint.py: the largest standardised rank sum over splits and channels, so no
Bonferroni over channels), and each significant split gives the shift of every channel in robust
sigmas of the two sides (at least the standard error of one trial's level).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rcbht_introspection.audit.changepoint import Change, WholeTest, find_changes, robust_sigma
from rcbht_introspection.audit.findings import Finding, sigmas
from rcbht_introspection.audit.settings import AuditSettings

SHOWN_CHANNELS = 3
"""Channels named in a change's message (all are in its detail)."""
SESSION_SEED = 7919
"""Seed offset of the level test (the sub-tasks use their index)."""


@dataclass(frozen=True)
class ChannelShift:
    channel: str
    before: float
    after: float
    sigma: float

    @property
    def shift_sigmas(self) -> float:
        return (self.after - self.before) / self.sigma


@dataclass(frozen=True)
class LevelChange:
    """A change within a session: the session's trials (input order), the split, the shifts."""

    trials: list[str]
    change: Change
    shifts: list[ChannelShift]


def channel_shifts(
    levels: np.ndarray, channels: list[str], floor: np.ndarray, change: Change
) -> list[ChannelShift]:
    """Every channel's shift at `change`, largest in sigmas first."""
    a, b = levels[change.start : change.split], levels[change.split : change.stop]
    shifts = []
    for j, name in enumerate(channels):
        na, nb = len(a), len(b)
        pooled = math.sqrt(
            (na * robust_sigma(a[:, j]) ** 2 + nb * robust_sigma(b[:, j]) ** 2) / (na + nb)
        )
        sigma = max(pooled, float(floor[j]), 1e-12)
        shifts.append(
            ChannelShift(name, float(np.median(a[:, j])), float(np.median(b[:, j])), sigma)
        )
    return sorted(shifts, key=lambda s: -abs(s.shift_sigmas))


def changes_within(
    trials: list[str],
    levels: np.ndarray,
    channels: list[str],
    floor: np.ndarray,
    settings: AuditSettings,
) -> tuple[list[LevelChange], WholeTest | None]:
    """The level changes of one session's trials (in input order), and its whole test."""
    if not channels or len(trials) < 2 * settings.min_segment:
        return [], None
    segmentation = find_changes(
        levels,
        settings.alpha,
        settings.permutations,
        [settings.seed, SESSION_SEED],
        1,
        settings.min_segment,
    )
    found = [
        LevelChange(trials, c, channel_shifts(levels, channels, floor, c))
        for c in segmentation.changes
    ]
    return found, segmentation.whole


def change_findings(changes: list[LevelChange], settings: AuditSettings) -> list[Finding]:
    """One finding per change of the level within a session."""
    found = []
    for lc in changes:
        change, shifts = lc.change, lc.shifts
        before, after = lc.trials[change.split - 1], lc.trials[change.split]
        top = ", ".join(
            f"{s.channel} {s.after - s.before:+.3g} ({sigmas(s.shift_sigmas)})"
            for s in shifts[:SHOWN_CHANNELS]
        )
        message = (
            f"free-motion wrench level shifts between {before} and {after} (in input order, "
            f"within one session): {top}; z {change.statistic:.2f}, p {change.p_value:.2g} "
            f"({settings.permutations} permutations)"
        )
        strength = {
            "statistic": "rank changepoint z over every channel (largest standardised "
            "Mann-Whitney sum over splits and channels)",
            "z": round(change.statistic, 4),
            "p": change.p_value,
            "permutations": settings.permutations,
            "alpha": settings.alpha,
            "largest_shift_sigmas": round(shifts[0].shift_sigmas, 2),
        }
        detail = {
            "before": [lc.trials[change.start], before],
            "after": [after, lc.trials[change.stop - 1]],
            "channels": [
                {
                    "channel": s.channel,
                    "before": s.before,
                    "after": s.after,
                    "sigma": s.sigma,
                    "shift_sigmas": round(s.shift_sigmas, 2),
                }
                for s in shifts
            ],
        }
        found.append(
            Finding(
                "session_change", message, (before, after), (), (before, after), strength, detail
            )
        )
    return found

"""Sessions: jumps of the free-motion wrench level between trials.

Each trial's level is the mean of every axis of every arm over its first FREE_MOTION_S seconds
(audit/facts.py), before the tool touches anything. A sensor re-biased, re-mounted or warmed up,
or another recording day, moves that level for every trial after it. The levels in trial order
are scanned as one multichannel sequence (audit/changepoint.py: the largest standardised rank
sum over splits and channels, so no Bonferroni over channels is needed), and each significant
split gives the shift of every channel in robust sigmas of the trial-to-trial spread (at least
the standard error of one trial's level).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from rcbht_introspection.audit.changepoint import Change, WholeTest, find_changes, robust_sigma
from rcbht_introspection.audit.facts import TrialFacts
from rcbht_introspection.audit.findings import Finding, sigmas
from rcbht_introspection.audit.settings import AuditSettings
from rcbht_introspection.io.trial import AXES

SHOWN_CHANNELS = 3
"""Channels named in a session finding's message (all are in its detail)."""
SESSION_SEED = 7919
"""Seed offset of the session test (the sub-tasks use their index)."""


@dataclass(frozen=True)
class ChannelShift:
    channel: str
    before: float
    after: float
    sigma: float

    @property
    def shift_sigmas(self) -> float:
        return (self.after - self.before) / self.sigma


@dataclass
class Sessions:
    """The level of every trial, the changes between sessions and the sessions they leave."""

    trials: list[str]
    channels: list[str]
    levels: np.ndarray
    changes: list[tuple[Change, list[ChannelShift]]] = field(default_factory=list)
    whole: WholeTest | None = None
    """The test of all the trials' levels (None: too few trials)."""


def level_matrix(facts: list[TrialFacts]) -> tuple[list[str], np.ndarray, np.ndarray]:
    """(channel names, (trials, channels) levels, (channels,) noise floor) of the arms every
    trial has."""
    arms = sorted(set.intersection(*(set(f.level) for f in facts))) if facts else []
    channels = [f"{arm}.{axis}" for arm in arms for axis in AXES]
    levels = np.array([[v for arm in arms for v in f.level[arm]] for f in facts], dtype=np.float64)
    noise = np.array(
        [[v for arm in arms for v in f.level_noise.get(arm, (0.0,) * len(AXES))] for f in facts],
        dtype=np.float64,
    )
    floor = np.median(noise, axis=0) if len(noise) else np.zeros(len(channels))
    return channels, levels.reshape(len(facts), len(channels)), floor


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


def analyse_sessions(facts: list[TrialFacts], settings: AuditSettings) -> Sessions:
    """Session changes of the trials' free-motion levels."""
    channels, levels, floor = level_matrix(facts)
    result = Sessions([f.name for f in facts], channels, levels)
    if not channels:
        return result
    segmentation = find_changes(
        levels,
        settings.alpha,
        settings.permutations,
        [settings.seed, SESSION_SEED],
        1,
        settings.min_segment,
    )
    result.whole = segmentation.whole
    result.changes = [(c, channel_shifts(levels, channels, floor, c)) for c in segmentation.changes]
    return result


def session_findings(sessions: Sessions, settings: AuditSettings) -> list[Finding]:
    """One finding per change of session."""
    found = []
    for change, shifts in sessions.changes:
        before, after = sessions.trials[change.split - 1], sessions.trials[change.split]
        top = ", ".join(
            f"{s.channel} {s.after - s.before:+.3g} ({sigmas(s.shift_sigmas)})"
            for s in shifts[:SHOWN_CHANNELS]
        )
        message = (
            f"free-motion wrench level jumps between {before} and {after}: {top}; z "
            f"{change.statistic:.2f}, p {change.p_value:.2g} ({settings.permutations} permutations)"
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
            "before": [sessions.trials[change.start], before],
            "after": [after, sessions.trials[change.stop - 1]],
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


def sessions_dict(sessions: Sessions) -> dict[str, object]:
    """The JSON of the sessions: channels, each session's trials and median level."""
    bounds = [0, *(c.split for c, _ in sessions.changes), len(sessions.trials)]
    parts = []
    for a, b in itertools.pairwise(bounds):
        if b > a:
            median = np.median(sessions.levels[a:b], axis=0) if sessions.channels else []
            parts.append(
                {
                    "first": sessions.trials[a],
                    "last": sessions.trials[b - 1],
                    "trials": b - a,
                    "level": [float(v) for v in median],
                }
            )
    whole = sessions.whole
    test = {"z": whole.statistic, "p": whole.p_value} if whole else None
    return {"channels": sessions.channels, "test": test, "sessions": parts}

"""Sessions: groups of trials recorded at one free-motion wrench level, whatever their order.

Each trial's level is the mean of every axis of every arm over its first FREE_MOTION_S seconds
(audit/facts.py), before the tool touches anything. A sensor re-biased, re-mounted or warmed up,
or another recording day, moves that level for every trial of its session. The levels of each
channel are sorted and split, largest gap first, wherever two consecutive levels are more than
GAP_SIGMAS apart in units of the spread of the levels on the two sides (their pooled robust
sigma, at least the standard error of one trial's level): a step far beyond the trial-to-trial
spread of a session. Trials share a session when they share a group on every channel; the order
of the inputs does not matter. The largest session is the reference; every other one is a
finding that names its trials and its level against the reference's. Within each session,
smaller shifts in input order are audit/level_changes.py's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rcbht_introspection.audit.changepoint import WholeTest, robust_sigma
from rcbht_introspection.audit.facts import TrialFacts
from rcbht_introspection.audit.findings import Finding, sigmas
from rcbht_introspection.audit.level_changes import LevelChange, change_findings, changes_within
from rcbht_introspection.audit.settings import AuditSettings
from rcbht_introspection.io.trial import AXES

GAP_SIGMAS = 6.0
"""A gap between consecutive sorted levels of a channel splits sessions when it is more than this
many pooled robust sigmas of the levels on its two sides (a normal sample of any realistic size
has no gap of even 3 sigmas between its middle values)."""
SHOWN_CHANNELS = 3
"""Channels named in a session finding's message (all are in its detail)."""
SHOWN_TRIALS = 8
"""Trials named in a session finding's message (all are in its trials)."""


@dataclass
class Sessions:
    """The level of every trial and the sessions they fall into (the reference first)."""

    trials: list[str]
    channels: list[str]
    levels: np.ndarray
    floor: np.ndarray
    """Per channel, the median standard error of one trial's level (the sensor's noise)."""
    groups: list[list[int]] = field(default_factory=list)
    """Trial indices of each session, in input order; the largest session first."""
    changes: list[LevelChange] = field(default_factory=list)
    """Shifts of the level within a session, in input order (audit/level_changes.py)."""
    whole: WholeTest | None = None
    """The changepoint test of the largest session's levels in input order (None: too few)."""

    def level(self, group: list[int]) -> np.ndarray:
        """The median level of each channel over the trials of `group`."""
        median: np.ndarray = np.median(self.levels[group], axis=0)
        return median


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


def pooled_sigma(a: np.ndarray, b: np.ndarray, floor: float) -> float:
    """The pooled robust sigma of two groups of levels, at least `floor` (and above 0)."""
    pooled = math.sqrt(
        (len(a) * robust_sigma(a) ** 2 + len(b) * robust_sigma(b) ** 2) / (len(a) + len(b))
    )
    return max(pooled, floor, 1e-12)


def channel_groups(values: np.ndarray, floor: float) -> list[list[int]]:
    """Indices of `values` split where consecutive sorted values are more than GAP_SIGMAS
    pooled sigmas apart (pooled_sigma of the two sides), largest gap first, recursively."""
    todo = [[int(i) for i in np.argsort(values, kind="stable")]]
    done: list[list[int]] = []
    while todo:
        group = todo.pop()
        v = values[group]
        if len(group) < 2:
            done.append(group)
            continue
        k = int(np.argmax(np.diff(v))) + 1
        if v[k] - v[k - 1] > GAP_SIGMAS * pooled_sigma(v[:k], v[k:], floor):
            todo.extend([group[:k], group[k:]])
        else:
            done.append(group)
    return done


def analyse_sessions(facts: list[TrialFacts], settings: AuditSettings) -> Sessions:
    """The sessions of the trials' free-motion levels (the same whatever their order), and the
    changes of the level within each in input order."""
    channels, levels, floor = level_matrix(facts)
    result = Sessions([f.name for f in facts], channels, levels, floor)
    key: list[list[int]] = [[] for _ in facts]
    for j in range(len(channels)):
        for g, group in enumerate(channel_groups(levels[:, j], float(floor[j]))):
            for i in group:
                key[i].append(g)
    by_key: dict[tuple[int, ...], list[int]] = {}
    for i, k in enumerate(key):
        by_key.setdefault(tuple(k), []).append(i)
    groups = list(by_key.values())
    # the largest first; ties by their trials' names, so the input order does not matter
    groups.sort(key=lambda g: (-len(g), sorted(result.trials[i] for i in g)))
    result.groups = groups if channels else [list(range(len(facts)))]
    for n, group in enumerate(result.groups):
        names = [result.trials[i] for i in group]
        found, whole = changes_within(names, levels[group], channels, floor, settings)
        result.changes.extend(found)
        if n == 0:
            result.whole = whole
    return result


def _shifts(sessions: Sessions, group: list[int]) -> list[dict[str, float | str]]:
    """Every channel of `group` against the reference session, largest in sigmas first."""
    ref = sessions.groups[0]
    mine, theirs = sessions.level(group), sessions.level(ref)
    rows: list[dict[str, float | str]] = []
    for j, name in enumerate(sessions.channels):
        a, b = sessions.levels[ref, j], sessions.levels[group, j]
        sigma = pooled_sigma(a, b, float(sessions.floor[j]))
        shift = float(mine[j] - theirs[j])
        rows.append(
            {
                "channel": name,
                "level": float(mine[j]),
                "reference": float(theirs[j]),
                "shift": shift,
                "sigma": sigma,
                "shift_sigmas": round(shift / sigma, 2),
            }
        )
    return sorted(rows, key=lambda r: -abs(float(r["shift_sigmas"])))


def session_findings(sessions: Sessions, settings: AuditSettings) -> list[Finding]:
    """One finding per session besides the reference (the largest): its trials and level; and
    one per change of the level within a session."""
    found = []
    ref = sessions.groups[0] if sessions.groups else []
    for group in sessions.groups[1:]:
        names = [sessions.trials[i] for i in group]
        rows = _shifts(sessions, group)
        top = ", ".join(
            f"{r['channel']} {float(r['level']):.3g} against {float(r['reference']):.3g} "
            f"({sigmas(float(r['shift_sigmas']))})"
            for r in rows[:SHOWN_CHANNELS]
        )
        message = (
            f"{len(names)} trial(s) recorded at another free-motion wrench level than the "
            f"{len(ref)} of the largest session: {', '.join(names[:SHOWN_TRIALS])}"
            f"{f' and {len(names) - SHOWN_TRIALS} more' if len(names) > SHOWN_TRIALS else ''}; {top}"
        )
        strength = {
            "statistic": "gap between sorted free-motion levels in pooled robust sigmas of the "
            f"two sides (a new session beyond {GAP_SIGMAS:g})",
            "gap_sigmas": GAP_SIGMAS,
            "largest_shift_sigmas": rows[0]["shift_sigmas"],
        }
        detail = {"trials": names, "reference_trials": len(ref), "channels": rows}
        found.append(Finding("session", message, tuple(names), (), None, strength, detail))
    return found + change_findings(sessions.changes, settings)


def sessions_dict(sessions: Sessions) -> dict[str, object]:
    """The JSON of the sessions: channels, the rule, each session's trials and median level."""
    whole = sessions.whole
    return {
        "channels": sessions.channels,
        "gap_sigmas": GAP_SIGMAS,
        "test": {"z": whole.statistic, "p": whole.p_value} if whole else None,
        "changes": [
            {
                "between": [lc.trials[lc.change.split - 1], lc.trials[lc.change.split]],
                "z": lc.change.statistic,
                "p": lc.change.p_value,
            }
            for lc in sessions.changes
        ],
        "sessions": [
            {
                "trials": [sessions.trials[i] for i in group],
                "count": len(group),
                "level": [float(v) for v in sessions.level(group)] if sessions.channels else [],
            }
            for group in sessions.groups
        ],
    }

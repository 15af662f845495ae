"""Sub-task durations over the trials: changes (of the labelling convention or of the procedure)
and outlying trials.

Each sub-task's log durations, in trial order, are tested for changepoints (audit/changepoint.py,
Bonferroni over the sub-tasks tested). A change counts when the medians on its two sides differ
by more than one sample period (the resolution of a duration). Two neighbouring sub-tasks that
change at the same trial in opposite directions are one *convention change*: the boundary
between them moved, so the same motion carries one label before and the other after. A change of
one sub-task alone is a *duration shift* (a new procedure or speed, or a label moved against the
start or end of the trial). Outliers are judged within the parts the changes leave: a robust z
of the log duration (median, robust sigma at least the resolution's), two-sided normal p-value,
Bonferroni over every duration tested; and the difference must matter: at least OUTLIER_MIN_S
seconds and OUTLIER_MIN_FRACTION of the part's median.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import norm

from rcbht_introspection.audit.changepoint import Change, WholeTest, find_changes, robust_sigma
from rcbht_introspection.audit.facts import TrialFacts
from rcbht_introspection.audit.settings import AuditSettings
from rcbht_introspection.task import Task

OUTLIER_MIN_TRIALS = 5
"""Fewest trials of a part for outliers to be judged in it."""
OUTLIER_MIN_S = 0.5
"""An outlying duration differs from its part's median by at least this many seconds: less is
within where a person labelling or a state machine publishing puts a boundary, whatever the
sub-task, and too little for a sub-task's words to differ."""
OUTLIER_MIN_FRACTION = 0.25
"""... and by at least this share of that median: a quarter more or less of a sub-task changes
what its words count; a scripted robot's spread, tiny in sigmas, is not that."""


@dataclass(frozen=True)
class Part:
    """Trials [start, stop) of one sub-task's sequence between changes."""

    start: int
    stop: int
    median_s: float
    sigma_log: float
    """Robust sigma of the log durations, at least the resolution's."""


@dataclass(frozen=True)
class DurationChange:
    """A changepoint of one sub-task's durations, with its two sides."""

    subtask: str
    change: Change
    before: Part
    after: Part
    shift_sigmas: float
    """(median log after - median log before) / the pooled robust sigma of the two sides."""


@dataclass
class SubtaskDurations:
    """One sub-task's durations in trial order and what the audit found in them."""

    subtask: str
    trials: list[str]
    seconds: list[float]
    rows: list[int] = field(default_factory=list)
    """Position of each trial among all the audited trials."""
    changes: list[DurationChange] = field(default_factory=list)
    parts: list[Part] = field(default_factory=list)
    outliers: list[tuple[int, float, float]] = field(default_factory=list)
    """(index, robust z, Bonferroni p) of each outlying duration."""
    whole: WholeTest | None = None
    """The changepoint test of all its trials (None: too few)."""


def between(r: SubtaskDurations, c: DurationChange) -> tuple[str, str]:
    """The last trial before a change and the first after it."""
    return r.trials[c.change.split - 1], r.trials[c.change.split]


def _log(seconds_: np.ndarray, period: float) -> np.ndarray:
    return np.log(np.asarray(seconds_, dtype=np.float64) + period)


def make_part(d: np.ndarray, start: int, stop: int, period: float) -> Part:
    """A part with its median and robust sigma (floored at the quantisation of a duration, the
    difference of two times rounded to a sample: sd period / sqrt 6, in log units)."""
    values = d[start:stop]
    median = float(np.median(values))
    floor = period / (math.sqrt(6.0) * (median + period)) if period > 0 else 1e-12
    return Part(start, stop, median, max(robust_sigma(_log(values, period)), floor))


def _pooled(a: Part, b: Part) -> float:
    na, nb = a.stop - a.start, b.stop - b.start
    return math.sqrt((na * a.sigma_log**2 + nb * b.sigma_log**2) / (na + nb))


def analyse_subtask(
    name: str,
    trials: list[tuple[int, str]],
    d: np.ndarray,
    settings: AuditSettings,
    tests: int,
    index: int,
) -> SubtaskDurations:
    """Changes and parts of one sub-task's durations `d` (seconds, in trial order) of `trials`
    (position among all trials, name)."""
    period = settings.period_s
    result = SubtaskDurations(
        name, [t for _, t in trials], [float(v) for v in d], [i for i, _ in trials]
    )
    x = _log(d, period)

    def resolved(start: int, split: int, stop: int) -> bool:
        return bool(abs(np.median(d[split:stop]) - np.median(d[start:split])) > period * (1 + 1e-9))

    segmentation = find_changes(
        x,
        settings.alpha,
        settings.permutations,
        [settings.seed, index],
        tests,
        settings.min_segment,
        resolved,
    )
    changes = segmentation.changes
    result.whole = segmentation.whole
    for c in changes:
        before = make_part(d, c.start, c.split, period)
        after = make_part(d, c.split, c.stop, period)
        shift = (np.median(x[c.split : c.stop]) - np.median(x[c.start : c.split])) / _pooled(
            before, after
        )
        result.changes.append(DurationChange(name, c, before, after, float(shift)))
    bounds = [0, *(c.split for c in changes), len(d)]
    result.parts = [make_part(d, a, b, period) for a, b in itertools.pairwise(bounds) if b > a]
    return result


def mark_outliers(results: list[SubtaskDurations], settings: AuditSettings) -> None:
    """Fill each result's outliers (Bonferroni over every duration of every sub-task)."""
    tested = sum(
        p.stop - p.start for r in results for p in r.parts if p.stop - p.start >= OUTLIER_MIN_TRIALS
    )
    for r in results:
        x = _log(np.asarray(r.seconds), settings.period_s)
        for part in r.parts:
            if part.stop - part.start < OUTLIER_MIN_TRIALS:
                continue
            seg = x[part.start : part.stop]
            z = (seg - np.median(seg)) / part.sigma_log
            p = np.minimum(1.0, 2.0 * norm.sf(np.abs(z)) * tested)
            off = np.abs(np.asarray(r.seconds[part.start : part.stop]) - part.median_s)
            matters = (off >= OUTLIER_MIN_S) & (off >= OUTLIER_MIN_FRACTION * part.median_s)
            for i in np.flatnonzero((p <= settings.alpha) & matters):
                r.outliers.append((part.start + int(i), float(z[i]), float(p[i])))


def analyse_durations(
    facts: list[TrialFacts], task: Task, settings: AuditSettings
) -> list[SubtaskDurations]:
    """Every sub-task of `task`: its durations over the trials that ran it, changes, outliers."""
    sequences = []
    for name in task.subtasks:
        have = [(i, f) for i, f in enumerate(facts) if name in f.durations]
        sequences.append(
            (name, [(i, f.name) for i, f in have], [f.durations[name] for _, f in have])
        )
    tests = sum(1 for _, t, _ in sequences if len(t) >= 2 * settings.min_segment)
    results = [
        analyse_subtask(name, trials, np.asarray(d, dtype=np.float64), settings, tests, j)
        for j, (name, trials, d) in enumerate(sequences)
    ]
    mark_outliers(results, settings)
    return results


def whole_dict(whole: WholeTest | None) -> dict[str, float] | None:
    """The test of a whole sequence as JSON (None: too few trials to test)."""
    if whole is None:
        return None
    return {"z": whole.statistic, "p": whole.p_value, "p_bonferroni": whole.p_adjusted}


def durations_dict(results: list[SubtaskDurations]) -> dict[str, object]:
    """The JSON of the durations: per sub-task, its parts, changes and outliers."""
    out: dict[str, object] = {}
    for r in results:
        out[r.subtask] = {
            "trials": len(r.trials),
            "test": whole_dict(r.whole),
            "median_s": float(np.median(r.seconds)) if r.seconds else None,
            "parts": [
                {
                    "first": r.trials[p.start],
                    "last": r.trials[p.stop - 1],
                    "trials": p.stop - p.start,
                    "median_s": p.median_s,
                    "sigma_log": p.sigma_log,
                }
                for p in r.parts
                if p.stop > p.start
            ],
            "changes": [
                {
                    "between": list(between(r, c)),
                    "z": c.change.statistic,
                    "p_bonferroni": c.change.p_adjusted,
                    "shift_sigmas": c.shift_sigmas,
                }
                for c in r.changes
            ],
            "outliers": [r.trials[i] for i, _, _ in r.outliers],
        }
    return out

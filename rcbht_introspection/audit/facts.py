"""What the audit keeps of one trial: sub-task durations, the free-motion wrench level and the
sensor's timing. A trial is read, reduced to these facts and let go, so a data set of any size
is audited in the memory of one trial."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rcbht_introspection.audit.agreement import window_features
from rcbht_introspection.io.hiro import DROPPED_STATE_TIMES
from rcbht_introspection.io.sensor_checks import REPEATED_METADATA, frozen_runs
from rcbht_introspection.io.trial import AXES, Trial
from rcbht_introspection.task import Task

FREE_MOTION_S = 0.3
"""Seconds at the start of a trial whose mean wrench is its free-motion level (before contact)."""
IMPORT_DROPS = ("unset", "repeated", "decreasing")
"""Stamp counts of `rcbht bag import` (trial info 'import', per arm) that the audit reports."""


@dataclass(frozen=True)
class Timing:
    """The sample clock of a trial: rate, period quartiles and gaps."""

    samples: int
    span_s: float
    rate_hz: float
    """(samples - 1) / span: new samples per second, whatever the jitter."""
    period_s: tuple[float, float, float]
    """First quartile, median and third quartile of the steps between samples."""
    gap_fence_s: float
    """A step longer than this is a gap: Tukey's far-out fence Q3 + 3 IQR of the trial's own
    steps, at least 1.5 median steps (a lost sample on a regular clock)."""
    gaps: int
    longest_gap_s: float
    missing_s: float
    """Time the gaps hold beyond one median step each."""


@dataclass(frozen=True)
class FrozenStretch:
    """A frozen run (io/sensor_checks.frozen_runs) of one arm."""

    arm: str
    t0: float
    t1: float
    samples: int


@dataclass(frozen=True, eq=False)
class TrialFacts:
    """One trial as the audit sees it."""

    name: str
    path: str
    phases: tuple[str, ...]
    durations: dict[str, float]
    """Seconds of each sub-task the trial ran to its end (occurrences of a repeated one summed)."""
    cut: str | None
    """The sub-task the trial ended in when that is not its task's last (not in `durations`)."""
    timing: Timing
    frozen: tuple[FrozenStretch, ...]
    dropped: dict[str, int]
    """Samples dropped or moved for their stamps, by reason (import and reader counts, all arms)."""
    messages: int | None
    """Wrench messages of the recording before the import (None: not an imported bag)."""
    level: dict[str, tuple[float, ...]]
    """Per arm, the mean of each axis over the first FREE_MOTION_S seconds."""
    level_noise: dict[str, tuple[float, ...]] = field(default_factory=dict)
    """Per arm, the standard error of that mean from the sensor's sample-to-sample noise."""
    dropped_states: tuple[dict[str, object], ...] = ()
    """State times the reader dropped (after the data or out of order: line, time, reason)."""
    windows: np.ndarray | None = None
    """Features of the trial's wrench windows, tared (audit/agreement.py; None: not kept)."""
    window_labels: tuple[str, ...] = ()


def durations_of(trial: Trial, task: Task) -> tuple[dict[str, float], str | None]:
    """(seconds per sub-task, the sub-task cut short or None): a trial that ends in another
    sub-task than its task's last was cut there, so that sub-task's length is not known."""
    bounds = trial.subtask_bounds()
    out: dict[str, float] = {}
    for name, start, end in bounds:
        out[name] = out.get(name, 0.0) + (end - start)
    cut = None
    if bounds and task.subtasks and bounds[-1][0] != task.subtasks[-1]:
        cut = bounds[-1][0]
        out.pop(cut, None)
    return out, cut


def timing_of(time: np.ndarray) -> Timing:
    """The clock of a sample time column (seconds)."""
    steps = np.diff(np.asarray(time, dtype=np.float64))
    if len(steps) == 0:
        return Timing(len(time), 0.0, 0.0, (0.0, 0.0, 0.0), 0.0, 0, 0.0, 0.0)
    q1, median, q3 = (float(v) for v in np.percentile(steps, [25, 50, 75]))
    fence = max(q3 + 3.0 * (q3 - q1), 1.5 * median)
    gaps = steps[steps > fence * (1 + 1e-9)]
    span = float(time[-1] - time[0])
    return Timing(
        samples=len(time),
        span_s=span,
        rate_hz=(len(time) - 1) / span if span > 0 else 0.0,
        period_s=(q1, median, q3),
        gap_fence_s=fence,
        gaps=len(gaps),
        longest_gap_s=float(gaps.max()) if len(gaps) else 0.0,
        missing_s=float(np.sum(gaps - median)),
    )


def level_of(time: np.ndarray, wrench: np.ndarray) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(mean of each axis over the first FREE_MOTION_S s, its standard error): the error is the
    sensor noise (robust sigma of successive differences / sqrt 2) over sqrt(samples averaged)."""
    values = np.asarray(wrench, dtype=np.float64)
    head = values[np.asarray(time) - time[0] < FREE_MOTION_S]
    if len(head) == 0:
        head = values[:1]
    diffs = np.diff(values, axis=0)
    noise = (
        1.4826 * np.median(np.abs(diffs), axis=0) / np.sqrt(2.0)
        if len(diffs)
        else np.zeros(len(AXES))
    )
    mean = head.mean(axis=0)
    return tuple(float(v) for v in mean), tuple(float(v) for v in noise / np.sqrt(len(head)))


def dropped_of(trial: Trial) -> tuple[dict[str, int], int | None]:
    """(samples dropped or moved for their stamps by reason, wrench messages before the import)."""
    dropped: dict[str, int] = {}
    messages: int | None = None
    imported = trial.metadata.get("import")
    arms = imported.get("arms") if isinstance(imported, dict) else None
    if isinstance(arms, dict):
        messages = 0
        for counts in arms.values():
            if not isinstance(counts, dict):
                continue
            messages += int(counts.get("messages", 0))
            for key in IMPORT_DROPS:
                dropped[key] = dropped.get(key, 0) + int(counts.get(key, 0))
    repeated = trial.metadata.get(REPEATED_METADATA)
    if isinstance(repeated, dict):
        for counts in repeated.values():
            for key, n in counts.items():
                dropped[key] = dropped.get(key, 0) + int(n)
    return {k: v for k, v in dropped.items() if v}, messages


def trial_facts(
    trial: Trial,
    path: Path | str,
    task: Task,
    frozen_samples: int,
    frozen_s: float,
    windows: bool = True,
) -> TrialFacts:
    """The facts of one trial (frozen runs with io/sensor_checks' thresholds; `windows`: keep
    its window features for the classifier check)."""
    durations, cut = durations_of(trial, task)
    frozen = tuple(
        FrozenStretch(arm, run.t0, run.t1, run.samples)
        for arm in trial.arms
        for run in frozen_runs(trial.time, trial.wrench[arm], frozen_samples, frozen_s)
    )
    levels = {arm: level_of(trial.time, trial.wrench[arm]) for arm in trial.arms}
    dropped, messages = dropped_of(trial)
    means = {arm: mean for arm, (mean, _) in levels.items()}
    states = trial.metadata.get(DROPPED_STATE_TIMES)
    features, labels = window_features(trial, means) if windows else (None, ())
    return TrialFacts(
        name=trial.name,
        path=str(path),
        phases=tuple(trial.phase_names),
        durations=durations,
        cut=cut,
        timing=timing_of(trial.time),
        frozen=frozen,
        dropped=dropped,
        messages=messages,
        level=means,
        level_noise={arm: noise for arm, (_, noise) in levels.items()},
        dropped_states=tuple(d for d in states if isinstance(d, dict))
        if isinstance(states, list)
        else (),
        windows=features,
        window_labels=labels,
    )

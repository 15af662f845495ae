"""Failure timeline of one verified trial: wrench, LLB words, score against threshold, alarm
and failure class over time, against the truth (onset, class)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure  # no pyplot: no backend, no global figure state
from numpy.typing import NDArray

from rcbht_introspection.io.trial import Trial
from rcbht_introspection.plots.timeline import PALETTE, subtask_colors
from rcbht_introspection.taxonomy.words import AXES, BEHAVIOR_LABELS, Level, TrialWords


def _shade_subtasks(axes: Sequence[Axes], trial: Trial) -> None:
    """Shade each true sub-task's span (stream time) on `axes`, one colour per sub-task."""
    bounds = trial.subtask_bounds()
    colors = subtask_colors([b[0] for b in bounds])
    t0 = float(trial.time[0])
    for ax in axes:
        for name, s, e in bounds:
            ax.axvspan(s - t0, e - t0, color=colors[name], alpha=0.12, lw=0)


def _plot_wrench(ax: Axes, t: NDArray[np.float64], trial: Trial, arm: str) -> None:
    """The arm's six wrench axes against stream time."""
    for k, axis in enumerate(AXES):
        ax.plot(t, trial.wrench[arm][:, k], lw=0.8, label=axis, color=PALETTE[k])
    ax.set_ylabel(f"{arm} wrench (N, N m)")
    ax.legend(loc="upper left", ncol=6, fontsize=7)


def _plot_llb_words(ax: Axes, words: TrialWords, arm: str) -> None:
    """The arm's LLB words as bars, one row per axis; labelled where wide enough to read."""
    label_colors = {lb: PALETTE[i % len(PALETTE)] for i, lb in enumerate(BEHAVIOR_LABELS)}
    llb = words.words.get(arm, {}).get(Level.BEHAVIOR, {})
    for row, axis in enumerate(AXES):
        for w in llb.get(axis, []):
            ax.barh(
                row,
                w.end - w.start,
                left=w.start,
                color=label_colors.get(w.label, "#999"),
                height=0.8,
            )
            if w.end - w.start > 0.8:
                ax.text((w.start + w.end) / 2, row, w.label, ha="center", va="center", fontsize=6)
    ax.set_yticks(range(len(AXES)), AXES, fontsize=7)
    ax.set_ylabel("LLB words")


def _plot_score(ax: Axes, times: NDArray[np.float64], score: NDArray[np.float64]) -> None:
    """The novelty score relative to its threshold (log scale), the threshold at 1."""
    ax.plot(times, np.maximum(score, 1e-3), color="black", lw=1.0, label="score / threshold")
    ax.axhline(1.0, color="#c44e52", ls="--", lw=1.0, label="threshold")
    ax.set_yscale("log")
    ax.set_ylabel("novelty")


def _mark_onset_and_alarm(axes: Sequence[Axes], onset: float | None, alarm: float | None) -> None:
    """The true onset (red line) and the alarm (dotted black line) on every row."""
    for ax in axes:
        if onset is not None:
            ax.axvline(onset, color="#c44e52", lw=1.2)
        if alarm is not None:
            ax.axvline(alarm, color="black", ls=":", lw=1.2)


def _plot_classes(
    ax: Axes, classes_over_time: Sequence[tuple[float, str]], truth: str, end: float
) -> None:
    """The predicted class over time: green while it is the true class, orange otherwise."""
    ax.set_yticks([])
    points = list(classes_over_time)
    for (g, cls), nxt in zip(points, [*points[1:], (end, "")], strict=False):
        ok = cls == truth
        ax.axvspan(g, nxt[0], color="#55a868" if ok else "#dd8452", alpha=0.6, lw=0)
    if points:
        ax.text(points[-1][0], 0.5, f" {points[-1][1]}", va="center", fontsize=8)
    ax.set_ylabel("class")
    ax.set_xlabel("stream time (s)")


def plot_failure_timeline(
    trial: Trial,
    words: TrialWords,
    times: NDArray[np.float64],
    score: NDArray[np.float64],
    alarm: float | None,
    onset_estimate: float | None,
    classes_over_time: Sequence[tuple[float, str]],
    truth: str,
    onset: float | None,
    path: Path,
) -> Path:
    """Four rows sharing the time axis; writes `path` (PNG)."""
    fig = Figure(figsize=(11, 8.5), constrained_layout=True)
    ax_w, ax_l, ax_s, ax_c = fig.subplots(
        4, 1, sharex=True, gridspec_kw={"height_ratios": [3, 2, 2, 1]}
    )
    t = np.asarray(trial.time, dtype=float) - float(trial.time[0])
    arm = trial.arms[-1]
    _shade_subtasks((ax_w, ax_s), trial)
    _plot_wrench(ax_w, t, trial, arm)
    _plot_llb_words(ax_l, words, arm)
    _plot_score(ax_s, times, score)
    _mark_onset_and_alarm((ax_w, ax_l, ax_s, ax_c), onset, alarm)
    ax_s.legend(loc="upper left", fontsize=7)
    _plot_classes(ax_c, classes_over_time, truth, float(t[-1]))
    alarm_text = (
        "no alarm" if alarm is None else f"alarm {alarm:.2f} s (onset est. {onset_estimate:.2f} s)"
    )
    onset_text = "" if onset is None else f", onset {onset:.2f} s"
    fig.suptitle(f"{trial.name}: truth {truth}{onset_text}; {alarm_text}", fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path

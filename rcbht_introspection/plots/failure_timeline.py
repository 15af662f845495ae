"""Failure timeline of one verified trial: wrench, LLB words, score against threshold, alarm
and failure class over time, against the truth (onset, class)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure  # no pyplot: no backend, no global figure state
from numpy.typing import NDArray

from rcbht_introspection.io.trial import Trial
from rcbht_introspection.plots.timeline import PALETTE, subtask_colors
from rcbht_introspection.taxonomy.words import AXES, BEHAVIOR_LABELS, Level, TrialWords


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
    bounds = trial.subtask_bounds()
    colors = subtask_colors([b[0] for b in bounds])
    for ax in (ax_w, ax_s):
        for name, s, e in bounds:
            s0, e0 = s - float(trial.time[0]), e - float(trial.time[0])
            ax.axvspan(s0, e0, color=colors[name], alpha=0.12, lw=0)
    for k, axis in enumerate(AXES):
        ax_w.plot(t, trial.wrench[arm][:, k], lw=0.8, label=axis, color=PALETTE[k])
    ax_w.set_ylabel(f"{arm} wrench (N, N m)")
    ax_w.legend(loc="upper left", ncol=6, fontsize=7)
    label_colors = {lb: PALETTE[i % len(PALETTE)] for i, lb in enumerate(BEHAVIOR_LABELS)}
    llb = words.words.get(arm, {}).get(Level.BEHAVIOR, {})
    for row, axis in enumerate(AXES):
        for w in llb.get(axis, []):
            ax_l.barh(
                row,
                w.end - w.start,
                left=w.start,
                color=label_colors.get(w.label, "#999"),
                height=0.8,
            )
            if w.end - w.start > 0.8:
                ax_l.text((w.start + w.end) / 2, row, w.label, ha="center", va="center", fontsize=6)
    ax_l.set_yticks(range(len(AXES)), AXES, fontsize=7)
    ax_l.set_ylabel("LLB words")
    ax_s.plot(times, np.maximum(score, 1e-3), color="black", lw=1.0, label="score / threshold")
    ax_s.axhline(1.0, color="#c44e52", ls="--", lw=1.0, label="threshold")
    ax_s.set_yscale("log")
    ax_s.set_ylabel("novelty")
    for ax in (ax_w, ax_l, ax_s, ax_c):
        if onset is not None:
            ax.axvline(onset, color="#c44e52", lw=1.2)
        if alarm is not None:
            ax.axvline(alarm, color="black", ls=":", lw=1.2)
    ax_s.legend(loc="upper left", fontsize=7)
    ax_c.set_yticks([])
    end = float(t[-1])
    points = list(classes_over_time)
    for (g, cls), nxt in zip(points, [*points[1:], (end, "")], strict=False):
        ok = cls == truth
        ax_c.axvspan(g, nxt[0], color="#55a868" if ok else "#dd8452", alpha=0.6, lw=0)
    if points:
        ax_c.text(points[-1][0], 0.5, f" {points[-1][1]}", va="center", fontsize=8)
    ax_c.set_ylabel("class")
    ax_c.set_xlabel("stream time (s)")
    alarm_text = (
        "no alarm" if alarm is None else f"alarm {alarm:.2f} s (onset est. {onset_estimate:.2f} s)"
    )
    onset_text = "" if onset is None else f", onset {onset:.2f} s"
    fig.suptitle(f"{trial.name}: truth {truth}{onset_text}; {alarm_text}", fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path

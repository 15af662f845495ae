"""Plot of a trial's action grammar: per axis the wrench, primitive/MC/LLB label bands, sub-tasks.

In the spirit of the paper's colour-coded figure. Matplotlib lives here, never in the pure core.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib
from matplotlib.figure import Figure  # no pyplot: no backend, no global figure state

from rcbht_introspection.io.trial import Trial
from rcbht_introspection.taxonomy.words import AXES, Level, TrialWords

BAND_LEVELS: tuple[Level, ...] = (Level.PRIMITIVE, Level.COMPOSITION, Level.BEHAVIOR)
BAND_NAMES = {Level.PRIMITIVE: "prim", Level.COMPOSITION: "MC", Level.BEHAVIOR: "LLB"}


def _colours(labels: tuple[str, ...]) -> dict[str, tuple[float, float, float, float]]:
    """One stable colour per label of a vocabulary."""
    cmap = matplotlib.colormaps["tab10"]
    return {label: cmap(i % 10) for i, label in enumerate(labels)}


def plot_trial(trial: Trial, words: TrialWords, out: Path, arm: str | None = None) -> Path:
    """Draw six axes (signal + three label bands each) with sub-task boundaries into `out`."""

    arm = arm or (trial.arms[0] if trial.arms else "R")
    wrench = trial.wrench[arm]
    fig = Figure(figsize=(14, 2.2 * len(AXES)))
    axes = fig.subplots(len(AXES), 1, sharex=True)
    colours = {level: _colours(level.labels) for level in BAND_LEVELS}
    for a, (ax, name) in enumerate(zip(axes, AXES, strict=True)):
        y = wrench[:, a]
        ax.plot(trial.time, y, color="black", linewidth=0.7)
        lo, hi = (float(y.min()), float(y.max())) if len(y) else (0.0, 1.0)
        span = (hi - lo) or 1.0
        band_h = 0.12 * span
        for b, level in enumerate(BAND_LEVELS):
            base = lo - (b + 1) * 1.15 * band_h
            for w in words.axis_words(arm, level, name):
                ax.broken_barh(
                    [(w.start, max(w.end - w.start, 1e-3))], (base, band_h),
                    facecolors=colours[level].get(w.label, "grey"), edgecolor="none",
                )  # fmt: skip
                if level is Level.BEHAVIOR and w.end - w.start > 0.02 * trial.end_time:
                    ax.text((w.start + w.end) / 2, base + band_h / 2, w.label,
                            ha="center", va="center", fontsize=6)  # fmt: skip
            ax.text(trial.time[0] if len(trial.time) else 0, base + band_h / 2,
                    BAND_NAMES[level] + " ", ha="right", va="center", fontsize=6)  # fmt: skip
        for _, start, _end in trial.subtask_bounds()[1:]:
            ax.axvline(start, color="red", linestyle="--", linewidth=0.8)
        ax.set_ylabel(name)
        ax.set_ylim(lo - 4 * 1.15 * band_h, hi + 0.05 * span)
    for subtask, start, end in trial.subtask_bounds():
        axes[0].text((start + end) / 2, axes[0].get_ylim()[1], subtask, ha="center",
                     va="bottom", fontsize=8, color="red")  # fmt: skip
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(f"{trial.name}: RCBHT primitives, motion compositions, low-level behaviours")
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    return out

"""Figures of the realism report (`rcbht sim-report`): simulated vs real HIRO sets."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure  # no pyplot: no backend, no global figure state
from numpy.typing import NDArray

from rcbht_introspection.io.hiro import find_trials, read_trial
from rcbht_introspection.io.trial import SUBTASKS
from rcbht_introspection.sim.realism import SetStats
from rcbht_introspection.taxonomy.words import AXES, BEHAVIOR_LABELS

LABEL_COLORS: dict[str, str] = {
    "FX": "#9e9e9e", "CT": "#d62728", "PS": "#1f77b4", "PL": "#ff7f0e",
    "AL": "#2ca02c", "SH": "#9467bd", "U": "#8c564b", "N": "#e377c2",
}  # fmt: skip
"""One colour per LLB label, shared by every panel."""


def plot_label_frequencies(real: SetStats, sim: SetStats, path: Path) -> None:
    """Stacked LLB label frequencies per sub-task and axis, real beside simulated."""

    fig = Figure(figsize=(16, 4.2))
    axes = fig.subplots(1, len(SUBTASKS), sharey=True)
    for ax, subtask in zip(axes, SUBTASKS, strict=True):
        x = np.arange(len(AXES))
        for offset, stats, hatch in ((-0.2, real, ""), (0.2, sim, "//")):
            bottom = np.zeros(len(AXES))
            freqs = np.array([stats.frequencies(subtask, axis) for axis in AXES])
            for j, label in enumerate(BEHAVIOR_LABELS):
                ax.bar(
                    x + offset,
                    freqs[:, j],
                    0.38,
                    bottom=bottom,
                    color=LABEL_COLORS[label],
                    hatch=hatch,
                    edgecolor="white",
                    linewidth=0.3,
                    label=label if (offset < 0 and subtask == SUBTASKS[0]) else None,
                )
                bottom += freqs[:, j]
        ax.set_xticks(x, AXES)
        ax.set_title(f"{subtask} (left real, right sim)", fontsize=10)
    axes[0].set_ylabel("LLB label frequency")
    fig.legend(loc="center right", fontsize=8)
    fig.tight_layout(rect=(0, 0, 0.95, 1))
    fig.savefig(path, dpi=110)


def plot_variability(real: SetStats, sim: SetStats, path: Path) -> None:
    """Box plots of sub-task durations, |Fz| and Fz word counts: the spread of both sets."""

    fig = Figure(figsize=(16, 4.2))
    a1, a2, a3 = fig.subplots(1, 3)
    positions = np.arange(len(SUBTASKS)) * 3.0
    panels: tuple[tuple[Axes, Callable[[SetStats, str], NDArray[np.float64]], str], ...] = (
        (a1, lambda s, st: s.durations(st), "sub-task duration (s)"),
        (a2, lambda s, st: s.magnitudes(st, "Fz"), "mean |Fz| per trial (N)"),
        (a3, lambda s, st: s.counts(st, "Fz").astype(float), "LLB words on Fz per trial"),
    )
    for ax, getter, title in panels:
        r = ax.boxplot(
            [getter(real, st) for st in SUBTASKS],
            positions=positions - 0.5,
            widths=0.8,
            patch_artist=True,
        )
        s = ax.boxplot(
            [getter(sim, st) for st in SUBTASKS],
            positions=positions + 0.5,
            widths=0.8,
            patch_artist=True,
        )
        for box in r["boxes"]:
            box.set_facecolor("#9ecae1")
        for box in s["boxes"]:
            box.set_facecolor("#fdae6b")
        ax.set_xticks(positions, SUBTASKS)
        ax.set_title(title, fontsize=10)
    a1.legend([r["boxes"][0], s["boxes"][0]], ["real", "sim"], fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_example_trials(real_dir: Path, sim_dir: Path, path: Path) -> None:
    """The wrench of the first real and the first simulated trial, sub-task starts dashed."""

    fig = Figure(figsize=(16, 6))
    axes = fig.subplots(2, 2, sharex="col")
    for col, folder in enumerate((find_trials([real_dir])[0], find_trials([sim_dir])[0])):
        trial = read_trial(folder)
        w = trial.wrench["R"]
        for i, axis in enumerate(AXES[:3]):
            axes[0, col].plot(trial.time, w[:, i], lw=0.7, label=axis)
        for i, axis in enumerate(AXES[3:], start=3):
            axes[1, col].plot(trial.time, w[:, i], lw=0.7, label=axis)
        for row in (0, 1):
            for t in trial.state_times[1:]:
                axes[row, col].axvline(t, color="k", ls="--", lw=0.6)
            axes[row, col].legend(fontsize=7, loc="upper left")
        axes[0, col].set_title(f"{'real' if col == 0 else 'simulated'}: {trial.name}", fontsize=10)
        axes[0, col].set_ylabel("force (N)")
        axes[1, col].set_ylabel("moment (N m)")
        axes[1, col].set_xlabel("time (s); dashed: rotation, insertion, mating start")
    fig.tight_layout()
    fig.savefig(path, dpi=110)

"""The audit's figure (`rcbht audit --plot`): each sub-task's duration over the trials with its
changes and outliers, and the free-motion wrench level of every channel with the sessions.
Drawn from the JSON report (audit/report.report_dict), so a saved report can be drawn again."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure  # no pyplot: no backend, no global figure state

CHANGE_COLORS = {"convention_change": "#c44e52", "duration_shift": "#dd8452"}
SESSION_COLOR = "#8172b3"


def _index(report: dict[str, Any]) -> dict[str, int]:
    index: dict[str, int] = {}
    for i, trial in enumerate(report["trials"]):
        index.setdefault(trial["name"], i)
    return index


def _change_lines(ax: Axes, report: dict[str, Any], index: dict[str, int], subtask: str) -> None:
    """A vertical line between the two trials of every change of `subtask`."""
    for finding in report["findings"]:
        color = CHANGE_COLORS.get(finding["kind"])
        if color and subtask in finding["subtasks"] and finding["between"]:
            x = index[finding["between"][1]] - 0.5
            ax.axvline(x, color=color, linestyle="--", linewidth=1.2)


def _durations_panel(ax: Axes, report: dict[str, Any], index: dict[str, int], subtask: str) -> None:
    rows = [
        (i, t["durations_s"][subtask])
        for i, t in enumerate(report["trials"])
        if subtask in t["durations_s"]
    ]
    if not rows:
        ax.set_ylabel(subtask)
        return
    x, y = np.array(rows).T
    ax.plot(x, y, "o", markersize=3, color="#4c72b0")
    outliers = set(report["durations"][subtask]["outliers"])
    odd = [(i, d) for i, d in rows if report["trials"][i]["name"] in outliers]
    if odd:
        ox, oy = np.array(odd).T
        ax.plot(ox, oy, "x", markersize=7, color="#c44e52", label="outlier")
    for part in report["durations"][subtask]["parts"]:
        a, b = index[part["first"]], index[part["last"]]
        ax.hlines(part["median_s"], a - 0.4, b + 0.4, color="#55a868", linewidth=1.5)
    _change_lines(ax, report, index, subtask)
    if np.all(y > 0) and y.max() > 3 * y.min():  # log where lengths differ by factors
        ax.set_yscale("log")
    ax.set_ylabel(f"{subtask} (s)", fontsize=8)
    ax.grid(alpha=0.3)


def _levels_panel(ax: Axes, report: dict[str, Any], index: dict[str, int]) -> None:
    """Every channel's free-motion level in robust units (median 0, spread 1), and the sessions."""
    channels = report["sessions"]["channels"]
    arms = [c.split(".")[0] for c in channels[::6]]
    levels = np.array(
        [[v for arm in arms for v in t["level"].get(arm, [np.nan] * 6)] for t in report["trials"]]
    )
    if levels.size:
        centre = np.nanmedian(levels, axis=0)
        spread = np.nanmedian(np.abs(np.diff(levels, axis=0)), axis=0)
        scaled = (levels - centre) / np.where(spread > 0, spread, 1.0)
        for j, name in enumerate(channels):
            ax.plot(scaled[:, j], linewidth=0.8, label=name)
        ax.legend(fontsize=6, ncol=6, loc="upper left")
    for finding in report["findings"]:
        if finding["kind"] == "session":  # the trials of a session besides the largest
            for name in finding["trials"]:
                ax.axvline(index[name], color=SESSION_COLOR, linewidth=1.5, alpha=0.5)
        elif finding["kind"] == "session_change":  # a shift within a session, in input order
            ax.axvline(index[finding["between"][1]] - 0.5, color=SESSION_COLOR, linewidth=1.5)
    ax.set_ylabel("free-motion level\n(robust units)", fontsize=8)
    ax.grid(alpha=0.3)


def plot_audit(report: dict[str, Any], out: Path | str) -> Path:
    """Write the figure of a JSON audit report to `out` (PNG); returns the path."""
    subtasks = list(report["task"]["subtasks"])
    index = _index(report)
    fig = Figure(figsize=(8.0, 1.6 * (len(subtasks) + 1) + 0.6))
    axes = fig.subplots(len(subtasks) + 1, 1, sharex=True, squeeze=False)[:, 0]
    for ax, subtask in zip(axes, subtasks, strict=False):
        _durations_panel(ax, report, index, subtask)
    _levels_panel(axes[-1], report, index)
    axes[-1].set_xlabel("trial (in audit order)")
    fig.suptitle(
        "sub-task durations (dashed: red convention change, orange duration shift) and sessions",
        fontsize=9,
    )
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    return out

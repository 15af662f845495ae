"""Plot of a replay evaluation: /task_state over time against the true sub-task, per trial."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from matplotlib.figure import Figure  # no pyplot: no backend, no global figure state
from matplotlib.patches import Patch

UNKNOWN_COLOR = "#bbbbbb"
PALETTE = ("#4c72b0", "#dd8452", "#55a868", "#c44e52", "#8172b3", "#937860", "#da8bc3", "#8c8c8c")
"""Colours of the sub-tasks in the order they first appear (HIRO's four keep theirs)."""


def subtask_colors(names: list[str]) -> dict[str, str]:
    """A colour per sub-task name, in order of appearance; 'unknown' is grey."""
    ordered = list(dict.fromkeys(n for n in names if n != "unknown"))
    colors = {n: PALETTE[i % len(PALETTE)] for i, n in enumerate(ordered)}
    return {**colors, "unknown": UNKNOWN_COLOR}


def _spans(
    changes: list[tuple[float, str]], initial: str, end: float
) -> list[tuple[float, float, str]]:
    """(start, end, state) spans of a step timeline."""
    points = [(0.0, initial), *[(max(0.0, t), s) for t, s in changes]]
    spans = []
    for (t0, s), (t1, _) in zip(points, [*points[1:], (end, "")], strict=True):
        if t1 > t0:
            spans.append((t0, min(t1, end), s))
    return spans


def plot_timelines(result: dict[str, Any], path: Path, durations: dict[str, float]) -> Path:
    """One row pair (truth, /task_state) per trial; writes `path` (PNG)."""

    bags = result["per_bag"]
    colors = subtask_colors(
        [s for b in bags for s in [*b["truth"], b["initial_state"], *(c[1] for c in b["timeline"])]]
    )
    fig = Figure(figsize=(11, 0.9 + 0.75 * len(bags)))
    ax = fig.subplots()
    ticks, labels = [], []
    for i, b in enumerate(bags):
        end = durations[b["name"]]
        y = 2 * (len(bags) - 1 - i)
        truth_changes = [(t, s) for t, s in zip(b["truth_starts"], b["truth"], strict=True)]
        for row, spans in (
            (y + 0.9, _spans(truth_changes, "unknown", end)),
            (y, _spans([tuple(c) for c in b["timeline"]], b["initial_state"], end)),
        ):
            for t0, t1, s in spans:
                ax.barh(row, t1 - t0, left=t0, height=0.8, color=colors.get(s, "#000000"))
        ticks += [y + 0.9, y]
        labels += [f"{b['name']} truth", f"/task_state ({b['time_accuracy']:.0%})"]
    ax.set_yticks(ticks, labels, fontsize=8)
    ax.set_xlabel("stream time [s]")
    ax.set_title(
        f"live sub-task belief vs truth: subtask accuracy {result['subtask_accuracy']}, "
        f"time accuracy {result['time_accuracy']}"
    )
    ax.legend(
        handles=[Patch(color=c, label=s) for s, c in colors.items()],
        loc="upper center",
        bbox_to_anchor=(0.5, -0.25 if len(bags) < 4 else -0.12),
        ncol=5,
        fontsize=8,
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path

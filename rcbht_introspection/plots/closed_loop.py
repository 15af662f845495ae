"""Timeline of one closed-loop trial over ROS: the wrench, /task_state, the verifier's alarm and
class, and the planner's decisions (attempt with its correction, abort, stop), as they arrived."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure  # no pyplot: no backend, no global figure state
from matplotlib.patches import Patch

from rcbht_introspection.plots.timeline import PALETTE
from rcbht_introspection.replay.closed_loop import Timeline


def _decision_text(d: dict[str, object]) -> str:
    kind = str(d["kind"])
    if kind == "attempt":
        c = d["correction"]
        assert isinstance(c, dict)
        moved = ", ".join(f"{a} {v * (1e3 if a != 'yaw' else 1):+.1f}" for a, v in c.items() if v)
        return f"attempt {d['attempt']}" + (f" ({moved})" if moved else "")
    if kind == "abort":
        return f"abort: {d['failure_class']} {d['reason']}".strip()
    return f"stop: {d['reason']}"


def plot_closed_loop(timeline: Timeline, title: str, path: Path, rate: float = 1.0) -> Path:
    """Wrench over time with /task_state bands, alarms and decisions marked; saved to `path`.
    `rate`: the cell's seconds per wall second (the x axis is the cell's clock)."""
    fig = Figure(figsize=(12, 5.5), layout="constrained")
    ax, states = fig.subplots(2, 1, sharex=True, height_ratios=(4, 1))
    if timeline.wrench:
        w = np.asarray(timeline.wrench)
        for k, name in enumerate(("Fx", "Fy", "Fz")):
            ax.plot(w[:, 0] * rate, w[:, k + 1], lw=0.7, color=PALETTE[k], label=name)
    alarms = [t for t, alarm, _ in timeline.verdicts if alarm]
    for i, t in enumerate(alarms):
        if i == 0 or t - alarms[i - 1] > 1.0:  # the first verdict of each alarm
            ax.axvline(t * rate, color="#c44e52", lw=1.2, ls="--")
    top = ax.get_ylim()[1]
    for t, d in timeline.decisions:
        color = {"attempt": "#4c72b0", "abort": "#c44e52", "stop": "#55a868"}[str(d["kind"])]
        ax.axvline(t * rate, color=color, lw=1.5)
        ax.text(
            t * rate, top, " " + _decision_text(d), rotation=90, va="top", fontsize=7, color=color
        )
    ax.set_ylabel("wrench (N)")
    ax.legend(loc="lower left", fontsize=7, ncol=3)
    ax.set_title(f"{title}; dashed: the verifier's alarm")
    _plot_states(states, timeline, rate)
    fig.savefig(path, dpi=110)
    return path


def _plot_states(ax: Axes, timeline: Timeline, rate: float) -> None:
    """/task_state as coloured bands, one colour per state name (legend)."""
    names = sorted({s for _, s in timeline.states})
    end_of_run = timeline.wrench[-1][0] if timeline.wrench else 0.0
    for (t, s), nxt in zip(timeline.states, [*timeline.states[1:], None], strict=True):
        end = nxt[0] if nxt else max(end_of_run, t)
        color = PALETTE[names.index(s) % len(PALETTE)]
        ax.barh(0, (end - t) * rate, left=t * rate, color=color, height=0.8)
    handles = [Patch(color=PALETTE[i % len(PALETTE)], label=n) for i, n in enumerate(names)]
    ax.legend(handles=handles, loc="upper left", fontsize=7, ncol=len(names) or 1)
    ax.set_yticks([0], ["/task_state"])
    ax.set_xlabel("seconds on the cell's clock (wall seconds x rate)")

"""The paper's learning-curve figure with a std band (matplotlib lives only here)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from matplotlib.figure import Figure  # no pyplot: no backend, no global figure state


def plot_learning_curve(results: list[dict[str, Any]], out: Path | str, title: str = "") -> Path:
    """Accuracy vs number of training trials (mean +- std over permutations) per result,
    with the duration-only reference as a dashed curve."""

    fig = Figure(figsize=(6.4, 4.0))
    ax = fig.subplots()
    for result in results:
        label = f"{result['classifier']} / {result['encoding']}"
        for curve, style, name in (
            (result["curve"], "-", label),
            (
                result["duration_baseline"]["curve"],
                "--",
                f"{label}: duration only (RF on log duration)",
            ),
        ):
            x = [p["n_train_trials"] for p in curve]
            mean = [p["mean"] for p in curve]
            std = [p["std"] for p in curve]
            (line,) = ax.plot(x, mean, style, label=name)
            ax.fill_between(
                x, [m - s for m, s in zip(mean, std, strict=True)],
                [min(1.0, m + s) for m, s in zip(mean, std, strict=True)],
                color=line.get_color(), alpha=0.2 if style == "-" else 0.08,
            )  # fmt: skip
    ax.set_xlabel("training trials")
    ax.set_ylabel("validation accuracy (sub-task)")
    ax.set_ylim(0.0, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    return out

"""The realism report of `rcbht sim-report`: tables (Markdown + JSON) and PNG figures comparing a
simulated set with the real HIRO set (statistics in sim/realism.py, figures in plots/realism.py)."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.hiro import find_trials, hiro_root
from rcbht_introspection.learn.evaluate import trial_kfold_accuracy
from rcbht_introspection.plots.realism import (
    plot_example_trials,
    plot_label_frequencies,
    plot_variability,
)
from rcbht_introspection.sim.realism import compare, engine_words, golden_words, set_stats
from rcbht_introspection.task import HIRO_TASK, task_of_folder
from rcbht_introspection.taxonomy.words import AXES


def default_real_dir() -> Path:
    """The real HIRO set: ../shared/data/hiro beside the working directory when it is there,
    else under `io.hiro.hiro_root()` ($RCBHT_HIRO_DATA first)."""
    real = "REAL_HIRO_ONE_SA_SUCCESS"
    beside_cwd = Path.cwd().parent / "shared" / "data" / "hiro" / real
    if not os.environ.get("RCBHT_HIRO_DATA") and beside_cwd.is_dir():
        return beside_cwd
    return hiro_root() / real


def _markdown(result: dict[str, Any], accuracy: dict[str, Any]) -> str:
    subtasks: dict[str, dict[str, Any]] = result["subtasks"]
    lines = [
        f"Real: {result['real']} ({result['n_real']} trials, golden LLB files); "
        f"simulated: {result['sim']} ({result['n_sim']} trials, batch engine).",
        "",
        f"Mean total-variation distance of the LLB label distributions over 4 sub-tasks x 6 axes: "
        f"**{result['mean_tv_distance']:.3f}** (0 = identical, 1 = disjoint).",
        "",
        "| sub-task | duration real (s) | duration sim (s) | TV distance Fx Fy Fz Mx My Mz | "
        "LLBs/trial Fz real | LLBs/trial Fz sim | distinct Fz sequences real | sim |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for subtask, entry in subtasks.items():
        d = entry["duration"]
        axes = entry["axes"]
        tv = " ".join(f"{axes[a]['tv_distance']:.2f}" for a in AXES)
        fz = axes["Fz"]
        lines.append(
            f"| {subtask} | {d['real_mean']:.1f} ± {d['real_std']:.1f} | "
            f"{d['sim_mean']:.1f} ± {d['sim_std']:.1f} | {tv} | "
            f"{fz['llb_count_real'][0]:.1f} ± {fz['llb_count_real'][1]:.1f} | "
            f"{fz['llb_count_sim'][0]:.1f} ± {fz['llb_count_sim'][1]:.1f} | "
            f"{fz['distinct_real']:.2f} | {fz['distinct_sim']:.2f} |"
        )
    lines += [
        "",
        "Mean |wrench| per sub-task (real / sim):",
        "",
        "| sub-task | " + " | ".join(AXES) + " |",
        "|---" * (len(AXES) + 1) + "|",
    ]
    for subtask, entry in subtasks.items():
        axes = entry["axes"]
        cells = [
            f"{axes[a]['mean_abs_real'][0]:.2f} / {axes[a]['mean_abs_sim'][0]:.2f}" for a in AXES
        ]
        lines.append(f"| {subtask} | " + " | ".join(cells) + " |")
    lines.append("")
    if accuracy.get("available"):
        lines.append(
            f"Sub-task classifier on the simulated trials (SVM, compact encoding, "
            f"{accuracy['folds']}-fold split by trial, {accuracy['samples']} samples): "
            f"accuracy **{accuracy['accuracy']:.3f}**."
        )
    else:
        lines.append(f"Classifier accuracy: not computed ({accuracy.get('why')}).")
    lines += ["", "Figures: llb_frequencies.png, variability.png, example_trials.png.", ""]
    return "\n".join(lines)


def write_report(sim_dir: Path, real_dir: Path | None, out_dir: Path) -> str:
    """Compute the comparison, write report.md, report.json and the PNGs; return a summary line."""
    real_dir = real_dir or default_real_dir()
    if not Path(real_dir).is_dir():
        raise InputError("real HIRO set not found (pass --real REAL_DIR)", path=real_dir)
    if not Path(sim_dir).is_dir():
        raise InputError("simulated set not found", path=sim_dir)
    tasks = {task_of_folder(folder) for folder in find_trials([Path(sim_dir)])} - {HIRO_TASK}
    if tasks:
        names = ", ".join(sorted(t.name or "/".join(t.subtasks) for t in tasks))
        raise InputError(
            f"the report compares snap-assembly trials with the real HIRO set; this set holds "
            f"{names} trials",
            path=sim_dir,
        )
    real = set_stats(Path(real_dir).name, Path(real_dir), golden_words)
    sim = set_stats(Path(sim_dir).name, Path(sim_dir), engine_words)
    result = compare(real, sim)
    accuracy = trial_kfold_accuracy(Path(sim_dir))
    result["classifier"] = accuracy
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    plot_label_frequencies(real, sim, out / "llb_frequencies.png")
    plot_variability(real, sim, out / "variability.png")
    plot_example_trials(Path(real_dir), Path(sim_dir), out / "example_trials.png")
    (out / "report.json").write_text(json.dumps(result, indent=1) + "\n")
    (out / "report.md").write_text(_markdown(result, accuracy))
    acc = f", SVM accuracy {accuracy['accuracy']:.3f}" if accuracy.get("available") else ""
    return (
        f"wrote {out}/report.md (+ .json, 3 PNG): mean LLB TV distance "
        f"{result['mean_tv_distance']:.3f} over {len(real.trials)} real / {len(sim.trials)} sim trials{acc}"
    )

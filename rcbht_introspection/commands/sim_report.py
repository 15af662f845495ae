"""The realism report of `rcbht sim-report`: tables (Markdown + JSON) and PNG figures comparing a
simulated set with the real HIRO set. Plotting lives here, outside the pure sim package."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.hiro import find_trials, read_trial
from rcbht_introspection.io.trial import SUBTASKS
from rcbht_introspection.sim.realism import SetStats, compare, engine_words, golden_words, set_stats
from rcbht_introspection.taxonomy.words import AXES, BEHAVIOR_LABELS

LABEL_COLORS: dict[str, str] = {
    "FX": "#9e9e9e", "CT": "#d62728", "PS": "#1f77b4", "PL": "#ff7f0e",
    "AL": "#2ca02c", "SH": "#9467bd", "U": "#8c564b", "N": "#e377c2",
}  # fmt: skip


def default_real_dir() -> Path:
    """$RCBHT_HIRO_DATA/REAL_HIRO_ONE_SA_SUCCESS, else ../shared/data/hiro/... beside the checkout."""
    root = os.environ.get("RCBHT_HIRO_DATA")
    if root:
        return Path(root) / "REAL_HIRO_ONE_SA_SUCCESS"
    candidates = [
        Path.cwd().parent / "shared" / "data" / "hiro",
        Path(__file__).resolve().parents[2].parent / "shared" / "data" / "hiro",
    ]
    for base in candidates:
        if (base / "REAL_HIRO_ONE_SA_SUCCESS").is_dir():
            return base / "REAL_HIRO_ONE_SA_SUCCESS"
    return candidates[0] / "REAL_HIRO_ONE_SA_SUCCESS"


def classifier_accuracy(sim_dir: Path, folds: int = 4) -> dict[str, object]:
    """Trial-grouped k-fold SVM (compact encoding) accuracy of the sub-task classifier, if present."""
    from rcbht_introspection.grammar.encoding.cache import SampleCache
    from rcbht_introspection.learn import data, models

    samples = data.load_samples([sim_dir], words="engine")
    trials = sorted({s.trial for s in samples})
    if len(trials) < folds:
        return {"available": False, "why": f"only {len(trials)} trials"}
    correct = total = 0
    cache = SampleCache()  # every fold encodes the same samples
    for k in range(folds):
        test = set(trials[k::folds])
        train = [s for s in samples if s.trial not in test]
        held = [s for s in samples if s.trial in test]
        model = models.train_model(
            train, classifier="svm", encoding="compact", random_state=0, cache=cache
        )
        predicted = model.predict_samples(held)
        correct += sum(p == s.subtask for p, s in zip(predicted, held, strict=True))
        total += len(held)
    return {"available": True, "folds": folds, "samples": total, "accuracy": correct / total}


def _frequency_figure(real: SetStats, sim: SetStats, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(SUBTASKS), figsize=(16, 4.2), sharey=True)
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
    plt.close(fig)


def _variability_figure(real: SetStats, sim: SetStats, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(16, 4.2))
    positions = np.arange(len(SUBTASKS)) * 3.0
    for ax, getter, title in (
        (a1, lambda s, st: s.durations(st), "sub-task duration (s)"),
        (a2, lambda s, st: s.magnitudes(st, "Fz"), "mean |Fz| per trial (N)"),
        (a3, lambda s, st: s.counts(st, "Fz").astype(float), "LLB words on Fz per trial"),
    ):
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
    plt.close(fig)


def _example_figure(real_dir: Path, sim_dir: Path, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(16, 6), sharex="col")
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
    plt.close(fig)


def _markdown(result: dict[str, object], accuracy: dict[str, object]) -> str:
    subtasks: dict[str, dict] = result["subtasks"]  # type: ignore[assignment]
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
    real = set_stats(Path(real_dir).name, Path(real_dir), golden_words)
    sim = set_stats(Path(sim_dir).name, Path(sim_dir), engine_words)
    result = compare(real, sim)
    accuracy = classifier_accuracy(Path(sim_dir))
    result["classifier"] = accuracy
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    _frequency_figure(real, sim, out / "llb_frequencies.png")
    _variability_figure(real, sim, out / "variability.png")
    _example_figure(Path(real_dir), Path(sim_dir), out / "example_trials.png")
    (out / "report.json").write_text(json.dumps(result, indent=1) + "\n")
    (out / "report.md").write_text(_markdown(result, accuracy))
    acc = f", SVM accuracy {accuracy['accuracy']:.3f}" if accuracy.get("available") else ""
    return (
        f"wrote {out}/report.md (+ .json, 3 PNG): mean LLB TV distance "
        f"{result['mean_tv_distance']:.3f} over {len(real.trials)} real / {len(sim.trials)} sim trials{acc}"
    )

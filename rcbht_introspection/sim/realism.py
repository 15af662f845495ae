"""Realism statistics of a simulated set against a real one (pure numbers, no plotting).

Per sub-task and axis: the LLB label frequencies (each LLB counted in every sub-task its span
overlaps, as the spec 2.7 split does), their total-variation distance sim vs real, and the
trial-to-trial variability (sub-task durations, LLB counts, mean |F|, distinct label sequences).
Real words come from the trials' golden/ files; simulated words from the batch taxonomy engine.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.hiro import find_trials, read_trial
from rcbht_introspection.io.rcbht_format import read_trial_words
from rcbht_introspection.io.trial import SUBTASKS, Trial
from rcbht_introspection.taxonomy.batch import label_trial
from rcbht_introspection.taxonomy.words import AXES, BEHAVIOR_LABELS, Level, TrialWords

WordSource = Callable[[Path, Trial], TrialWords]


@dataclass
class TrialStats:
    """One trial's per-sub-task, per-axis LLB label sequences and wrench summary."""

    name: str
    durations: dict[str, float]
    labels: dict[tuple[str, str], list[str]]
    """(sub-task, axis) -> the LLB labels overlapping that sub-task, in time order."""
    mean_abs: dict[tuple[str, str], float]
    """(sub-task, axis) -> mean |wrench| over the sub-task."""


@dataclass
class SetStats:
    """All trials of one data set."""

    name: str
    trials: list[TrialStats] = field(default_factory=list)

    def frequencies(self, subtask: str, axis: str) -> NDArray[np.float64]:
        """Relative frequency of each BEHAVIOR_LABELS label in (sub-task, axis) over the set."""
        counts = np.zeros(len(BEHAVIOR_LABELS))
        for t in self.trials:
            for label in t.labels.get((subtask, axis), []):
                if label in BEHAVIOR_LABELS:
                    counts[BEHAVIOR_LABELS.index(label)] += 1
        total = counts.sum()
        return counts / total if total else counts

    def durations(self, subtask: str) -> NDArray[np.float64]:
        """Duration (s) of the sub-task in each trial that has it."""
        return np.array([t.durations[subtask] for t in self.trials if subtask in t.durations])

    def counts(self, subtask: str, axis: str) -> NDArray[np.int_]:
        """Number of LLB words of (sub-task, axis) in each trial."""
        return np.array([len(t.labels.get((subtask, axis), [])) for t in self.trials])

    def magnitudes(self, subtask: str, axis: str) -> NDArray[np.float64]:
        """Mean |wrench| of (sub-task, axis) in each trial that has it."""
        return np.array(
            [t.mean_abs[(subtask, axis)] for t in self.trials if (subtask, axis) in t.mean_abs]
        )

    def distinct_fraction(self, subtask: str, axis: str) -> float:
        """Distinct LLB sequences / trials: 1.0 means no two trials share the same words."""
        seqs = [tuple(t.labels.get((subtask, axis), [])) for t in self.trials]
        return len(set(seqs)) / len(seqs) if seqs else 0.0


def trial_stats(trial: Trial, words: TrialWords, arm: str = "R") -> TrialStats:
    """Split one trial's LLB words over its sub-tasks (overlap rule) and summarise its wrench."""
    bounds = trial.subtask_bounds()
    labels: dict[tuple[str, str], list[str]] = {}
    mean_abs: dict[tuple[str, str], float] = {}
    wrench = trial.wrench[arm]
    for subtask, start, end in bounds:
        mask = (trial.time >= start) & (trial.time <= end)
        for i, axis in enumerate(AXES):
            seq = [
                w.label
                for w in words.axis_words(arm, Level.BEHAVIOR, axis)
                if w.end > start and w.start < end
            ]
            labels[(subtask, axis)] = seq
            if mask.any():
                mean_abs[(subtask, axis)] = float(np.abs(wrench[mask, i]).mean())
    return TrialStats(
        name=trial.name,
        durations={s: e - b for s, b, e in bounds},
        labels=labels,
        mean_abs=mean_abs,
    )


def golden_words(folder: Path, trial: Trial) -> TrialWords:
    """Words of a real trial from its golden/ folder (the original MATLAB output)."""

    golden = folder / "golden"
    if not golden.is_dir():
        raise InputError("no golden/ folder with the original RCBHT output", path=folder)
    return read_trial_words(golden, name=trial.name, levels=(Level.BEHAVIOR,))


def engine_words(folder: Path, trial: Trial) -> TrialWords:
    """Words of a (simulated) trial from the batch taxonomy engine."""
    return label_trial(trial)


def set_stats(
    name: str, dataset: Path, source: WordSource, only_success: bool = True, arm: str = "R"
) -> SetStats:
    """Statistics of every (successful, four-sub-task) trial of a data set folder."""
    stats = SetStats(name=name)
    for folder in find_trials([dataset]):
        trial = read_trial(folder)
        if only_success and (trial.outcome != "success" or len(trial.state_times) < len(SUBTASKS)):
            continue
        stats.trials.append(trial_stats(trial, source(folder, trial), arm))
    if not stats.trials:
        raise InputError("no successful trials with four state times", path=dataset)
    return stats


def total_variation(p: NDArray[np.float64], q: NDArray[np.float64]) -> float:
    """Total-variation distance of two label distributions (0 equal, 1 disjoint)."""
    return float(0.5 * np.abs(p - q).sum())


def compare(real: SetStats, sim: SetStats, subtasks: Iterable[str] = SUBTASKS) -> dict[str, Any]:
    """Side-by-side numbers: frequencies, distances, variability, per sub-task and axis."""
    out: dict[str, Any] = {
        "real": real.name,
        "sim": sim.name,
        "n_real": len(real.trials),
        "n_sim": len(sim.trials),
        "subtasks": {},
    }
    tvs = []
    for subtask in subtasks:
        entry: dict[str, object] = {}
        rd, sd = real.durations(subtask), sim.durations(subtask)
        entry["duration"] = {
            "real_mean": float(rd.mean()),
            "real_std": float(rd.std()),
            "sim_mean": float(sd.mean()),
            "sim_std": float(sd.std()),
        }
        axes: dict[str, object] = {}
        for axis in AXES:
            pr, ps = real.frequencies(subtask, axis), sim.frequencies(subtask, axis)
            tv = total_variation(pr, ps)
            tvs.append(tv)
            rc, sc = real.counts(subtask, axis), sim.counts(subtask, axis)
            rm, sm = real.magnitudes(subtask, axis), sim.magnitudes(subtask, axis)
            axes[axis] = {
                "real_freq": dict(zip(BEHAVIOR_LABELS, np.round(pr, 4).tolist(), strict=True)),
                "sim_freq": dict(zip(BEHAVIOR_LABELS, np.round(ps, 4).tolist(), strict=True)),
                "tv_distance": round(tv, 4),
                "llb_count_real": [float(rc.mean()), float(rc.std())],
                "llb_count_sim": [float(sc.mean()), float(sc.std())],
                "mean_abs_real": [float(rm.mean()), float(rm.std())],
                "mean_abs_sim": [float(sm.mean()), float(sm.std())],
                "distinct_real": round(real.distinct_fraction(subtask, axis), 4),
                "distinct_sim": round(sim.distinct_fraction(subtask, axis), 4),
            }
        entry["axes"] = axes
        out["subtasks"][subtask] = entry
    out["mean_tv_distance"] = round(float(np.mean(tvs)), 4)
    return out

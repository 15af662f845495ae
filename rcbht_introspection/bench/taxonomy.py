"""Benchmark of the batch taxonomy: label one real trial / all 46 in-process, and `rcbht label`.

Targets (issue 2): <= 20 ms per real trial in-process, <= 50 ms per trial end-to-end (parse,
taxonomy, write). Times are medians; CPU time (process_time) is reported next to wall time
because the machine is shared.
"""

from __future__ import annotations

import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from rcbht_introspection.io.hiro import find_trials, hiro_root, read_trial
from rcbht_introspection.io.rcbht_format import write_trial_words
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.taxonomy.batch import label_trial
from rcbht_introspection.taxonomy.config import TaxonomyConfig, default_config

REPEATS = 3


def _children_cpu() -> float:
    """CPU seconds (user + system) used by finished child processes."""

    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _ms(seconds: float) -> float:
    return round(seconds * 1000, 3)


def run(out_dir: Path) -> dict[str, Any]:
    """The batch engine on the REAL HIRO set: in process, as a pipeline, through the CLI."""

    dataset = hiro_root() / "REAL_HIRO_ONE_SA_SUCCESS"
    if not dataset.is_dir():
        return {"skipped": f"no data at {dataset}"}
    folders = find_trials([dataset])
    trials = [read_trial(f) for f in folders]
    config = default_config()
    label_trial(trials[0], config)  # warm-up
    load_start = os.getloadavg()[0]
    in_process = _label_in_process(trials, config)
    pipeline = _pipeline(folders, config)
    cli = _cli_label(dataset, folders)
    samples = statistics.median(len(t.time) for t in trials)
    return {
        "trials": len(trials),
        "median_samples_per_axis": samples,
        **in_process,
        **pipeline,
        **cli,
        "load_avg_1min_start": round(load_start, 2),
        "load_avg_1min_end": round(os.getloadavg()[0], 2),
        "targets": {"in_process_ms": 20, "end_to_end_ms": 50},
    }


def _label_in_process(trials: list[Trial], config: TaxonomyConfig) -> dict[str, float]:
    """label_trial per trial and over the whole set, best of REPEATS (CPU and wall)."""
    cpu: list[list[float]] = [[] for _ in trials]
    wall: list[list[float]] = [[] for _ in trials]
    all_cpu, all_wall = [], []
    for _ in range(REPEATS):
        c0, w0 = time.process_time(), time.perf_counter()
        for i, trial in enumerate(trials):
            c, w = time.process_time(), time.perf_counter()
            label_trial(trial, config)
            cpu[i].append(time.process_time() - c)
            wall[i].append(time.perf_counter() - w)
        all_cpu.append(time.process_time() - c0)
        all_wall.append(time.perf_counter() - w0)
    return {
        "label_one_trial_ms_median_cpu": _ms(statistics.median(min(c) for c in cpu)),
        "label_one_trial_ms_median_wall": _ms(statistics.median(min(w) for w in wall)),
        "label_all_trials_ms_cpu": _ms(min(all_cpu)),
        "label_all_trials_ms_wall": _ms(min(all_wall)),
    }


def _pipeline(folders: list[Path], config: TaxonomyConfig) -> dict[str, float]:
    """In-process pipeline per trial: parse + taxonomy + write the original layout."""
    pipe: list[float] = []
    pipe_cpu: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        for folder in folders:
            w, c = time.perf_counter(), time.process_time()
            write_trial_words(label_trial(read_trial(folder), config), Path(tmp) / folder.name)
            pipe.append(time.perf_counter() - w)
            pipe_cpu.append(time.process_time() - c)
    return {
        "pipeline_parse_label_write_ms_median_wall": _ms(statistics.median(pipe)),
        "pipeline_parse_label_write_ms_median_cpu": _ms(statistics.median(pipe_cpu)),
    }


def _cli_label(dataset: Path, folders: list[Path]) -> dict[str, float]:
    """End to end through the CLI: one process labels the whole dataset, and one single trial;
    and the start-up of `rcbht --help`."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "rcbht_introspection.cli", "label"]
        w, c = time.perf_counter(), _children_cpu()
        subprocess.run([*cmd, str(dataset), "--out", tmp], check=True, capture_output=True)
        dataset_wall = time.perf_counter() - w
        dataset_cpu = _children_cpu() - c
        singles = []
        for folder in folders[:5]:
            w = time.perf_counter()
            subprocess.run([*cmd, str(folder), "--out", tmp], check=True, capture_output=True)
            singles.append(time.perf_counter() - w)
        startup = []
        for _ in range(3):
            w = time.perf_counter()
            subprocess.run([*cmd, "--help"], check=True, capture_output=True)
            startup.append(time.perf_counter() - w)
    return {
        "cli_label_dataset_ms_per_trial_wall": _ms(dataset_wall / len(folders)),
        "cli_label_dataset_ms_per_trial_cpu": _ms(dataset_cpu / len(folders)),
        "cli_label_dataset_s_wall": round(dataset_wall, 3),
        "cli_label_single_trial_ms_wall_median": _ms(statistics.median(singles)),
        "cli_startup_ms_wall_median": _ms(statistics.median(startup)),
    }

"""Benchmark of the streaming engine: push() throughput, push_many() vs batch, finality delays,
and the causal and live profiles' agreement with the reference.

Targets (issue 3): >= 100,000 samples/s for single-sample push() of one arm; push_many() on a
whole trial as fast as the batch engine. CPU time (process_time) is the primary figure because
the machine is shared; wall time and the load average are reported next to it.
"""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from rcbht_introspection.io.hiro import find_trials, hiro_root, read_trial
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.taxonomy.batch import label_trial
from rcbht_introspection.taxonomy.config import TaxonomyConfig, default_config
from rcbht_introspection.taxonomy.primitives import axis_domain
from rcbht_introspection.taxonomy.stream import (
    ArmStream,
    StreamConfig,
    label_trial_streamed,
    load_stream_config,
)
from rcbht_introspection.taxonomy.words import AXES, Level, Word

THROUGHPUT_TRIALS = 10


def _ms(seconds: float) -> float:
    return round(seconds * 1000, 3)


def _percentile(values: Sequence[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q)) if values else float("nan")


def push_throughput(
    trials: list[Trial], stream_config: StreamConfig, config: TaxonomyConfig
) -> dict[str, float]:
    """Samples per second of ArmStream.push() one sample at a time (including finish())."""

    samples, cpu, wall = 0, 0.0, 0.0
    for trial in trials:
        t = trial.time.tolist()
        w = trial.wrench["R"].tolist()
        marks = list(trial.state_times)
        best_cpu, best_wall = float("inf"), float("inf")
        for _ in range(2):
            stream = ArmStream(config, stream_config)
            push, mark = stream.push, stream.mark_boundary
            m = 0
            c0, w0 = time.process_time(), time.perf_counter()
            for k in range(len(t)):
                while m < len(marks) and marks[m] < t[k]:
                    mark(marks[m])
                    m += 1
                push(t[k], w[k])
            stream.finish()
            best_cpu = min(best_cpu, time.process_time() - c0)
            best_wall = min(best_wall, time.perf_counter() - w0)
        samples += len(t)
        cpu += best_cpu
        wall += best_wall
    return {
        "samples": samples,
        "samples_per_s_cpu": round(samples / cpu),
        "samples_per_s_wall": round(samples / wall),
        "us_per_sample_cpu": round(cpu / samples * 1e6, 3),
    }


def finality_delays(
    trials: list[Trial],
    stream_config: StreamConfig | Callable[[Trial], StreamConfig],
    config: TaxonomyConfig,
) -> dict[str, dict[str, float]]:
    """Per level: how many samples (and seconds) after a word's last sample it is emitted."""

    delays: dict[Level, list[int]] = {level: [] for level in Level}
    seconds: dict[Level, list[float]] = {level: [] for level in Level}
    at_finish: dict[Level, int] = {level: 0 for level in Level}
    for trial in trials:
        time_ = trial.time
        w = trial.wrench["R"]
        period = float(np.median(np.diff(time_)))
        sc = stream_config(trial) if callable(stream_config) else stream_config
        stream = ArmStream(config, sc)
        marks = list(trial.state_times)
        m = 0

        def record(
            words: list[Word],
            k: int,
            finish: bool = False,
            time_: npt.NDArray[np.float64] = time_,
            period: float = period,
        ) -> None:
            for word in words:
                end = min(int(np.searchsorted(time_, word.end - 1e-9)), len(time_) - 1)
                d = k - end
                delays[word.level].append(d)
                seconds[word.level].append(d * period)
                at_finish[word.level] += finish

        for k in range(len(time_)):
            while m < len(marks) and marks[m] < time_[k]:
                record(stream.mark_boundary(marks[m]), max(k - 1, 0))
                m += 1
            record(stream.push(time_[k], w[k]), k)
        record(stream.finish(), len(time_) - 1, finish=True)
    out: dict[str, dict[str, float]] = {}
    for level in Level:
        d, s = delays[level], seconds[level]
        out[level.value] = {
            "words": len(d),
            "median_samples": _percentile(d, 50),
            "p99_samples": _percentile(d, 99),
            "median_s": round(_percentile(s, 50), 4),
            "p99_s": round(_percentile(s, 99), 4),
            "emitted_at_finish": at_finish[level],
        }
    return out


def agreement(
    trials: list[Trial], profile_config: StreamConfig, config: TaxonomyConfig
) -> dict[str, dict[str, str | float]]:
    """A stream profile vs reference per level: identical word sequences, share of time with
    equal labels, and the number of words of each."""

    same = {level: 0 for level in Level}
    total = {level: 0 for level in Level}
    agree = {level: 0 for level in Level}
    grid = {level: 0 for level in Level}
    counts = {level: [0, 0] for level in Level}
    for trial in trials:
        ref = label_trial(trial, config)
        got = label_trial_streamed(trial, config, profile_config)
        t = trial.time
        for level in Level:
            for axis in AXES:
                a, b = ref.axis_words("R", level, axis), got.axis_words("R", level, axis)
                total[level] += 1
                counts[level][0] += len(a)
                counts[level][1] += len(b)
                same[level] += [(x.label, x.start, x.end) for x in a] == [
                    (x.label, x.start, x.end) for x in b
                ]
                la = _labels_at(a, t)
                lb = _labels_at(b, t)
                agree[level] += int((la == lb).sum())
                grid[level] += len(t)
    return {
        level.value: {
            "identical_sequences": f"{same[level]}/{total[level]}",
            "identical_share": round(same[level] / total[level], 4),
            "time_share_same_label": round(agree[level] / grid[level], 4),
            "words_reference": counts[level][0],
            "words_profile": counts[level][1],
        }
        for level in Level
    }


def _labels_at(words: list[Word], t: npt.NDArray[np.float64]) -> npt.NDArray[np.object_]:
    """The label active at each time (the last word starting at or before it)."""
    if not words:
        return np.full(len(t), "", dtype=object)
    starts = np.array([w.start for w in words])
    labels = np.array([w.label for w in words], dtype=object)
    idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(words) - 1)
    return labels[idx]


def run(out_dir: Path) -> dict[str, Any]:

    root = hiro_root()
    real_dir, sim_dir = root / "REAL_HIRO_ONE_SA_SUCCESS", root / "SIM_HIRO_ONE_SA_SUCCESS"
    if not real_dir.is_dir():
        return {"skipped": f"no data at {real_dir}"}
    config = default_config()
    reference = load_stream_config("reference")
    causal = load_stream_config("causal")
    live = load_stream_config("live")
    real = [read_trial(f) for f in find_trials([real_dir])]
    sim = [read_trial(f) for f in find_trials([sim_dir])] if sim_dir.is_dir() else []
    load_start = os.getloadavg()[0]
    result: dict[str, Any] = {}

    result["push_reference"] = push_throughput(real[:THROUGHPUT_TRIALS], reference, config)
    result["push_causal"] = push_throughput(real[:THROUGHPUT_TRIALS], causal, config)
    result["push_live"] = push_throughput(real[:THROUGHPUT_TRIALS], live, config)

    # push_many on a whole trial vs the batch engine (per trial, CPU ms)
    many, batch = [], []
    for trial in real:
        c = time.process_time()
        label_trial_streamed(trial, config, reference, many=True)
        many.append(time.process_time() - c)
        c = time.process_time()
        label_trial(trial, config)
        batch.append(time.process_time() - c)
    result["push_many_vs_batch_real"] = {
        "push_many_ms_median_cpu": _ms(statistics.median(many)),
        "batch_ms_median_cpu": _ms(statistics.median(batch)),
        "ratio_push_many_over_batch": round(statistics.median(many) / statistics.median(batch), 3),
    }

    def given_domains(trial: Trial) -> StreamConfig:
        w = trial.wrench["R"]
        doms = {ax: axis_domain(w[:, AXES.index(ax)], config) for ax in config.domain_axes}
        return StreamConfig(moment_domains=doms)

    result["finality_delay_real"] = {
        "reference": finality_delays(real, reference, config),
        "reference_with_given_domains": finality_delays(real, given_domains, config),
        "causal": finality_delays(real, causal, config),
        "live": finality_delays(real, live, config),
    }
    result["live_finality_bound_s"] = live.finality_bound_s
    result["causal_agreement"] = {"REAL": agreement(real, causal, config)}
    result["live_agreement"] = {"REAL": agreement(real, live, config)}
    if sim:
        result["causal_agreement"]["SIM"] = agreement(sim, causal, config)
        result["live_agreement"]["SIM"] = agreement(sim, live, config)
    result["load_avg_1min_start"] = round(load_start, 2)
    result["load_avg_1min_end"] = round(os.getloadavg()[0], 2)
    result["targets"] = {
        "push_samples_per_s": 100_000,
        "push_many_vs_batch": "<= 1.0",
        "live_finality_p99_s": "<= 2.0 at every level",
    }
    return result

"""The streaming engine: streamed == batch on every shared and generated trial, intake policies,
bounded memory."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import SIM_FAILURE, SIM_SUCCESS, SOURCES, dataset_root, trial_folders

from rcbht_introspection.cli import main
from rcbht_introspection.io.conformance import first_difference
from rcbht_introspection.io.hiro import find_trials, read_trial
from rcbht_introspection.io.rcbht_format import level_path, read_words
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.taxonomy.batch import label_trial
from rcbht_introspection.taxonomy.config import default_config
from rcbht_introspection.taxonomy.primitives import axis_domain, block_stats, block_stats_one
from rcbht_introspection.taxonomy.stream import (
    ArmStream,
    StreamConfig,
    label_trial_streamed,
    load_stream_config,
)
from rcbht_introspection.taxonomy.words import AXES, LEVELS, Level, TrialWords, Word

DATASETS = [
    pytest.param(name, marks=pytest.mark.shared_data, id=name)
    for name in (
        "REAL_HIRO_ONE_SA_SUCCESS",
        "SIM_HIRO_ONE_SA_SUCCESS",
        "REAL_HIRO_ONE_SA_ERROR_CHARAC",
    )
] + [pytest.param(SIM_SUCCESS, id=SIM_SUCCESS), pytest.param(SIM_FAILURE, id=SIM_FAILURE)]
"""The shared HIRO sets and the sets generated at test time."""


def key(w: Word) -> tuple:
    return (w.label, w.start, w.end, w.features, w.sublabels)


def assert_same(batch: TrialWords, streamed: TrialWords) -> None:
    for level in LEVELS:
        for axis in AXES:
            a = [key(w) for w in batch.axis_words("R", level, axis)]
            b = [key(w) for w in streamed.axis_words("R", level, axis)]
            assert a == b, (batch.name, level.value, axis)


# --------------------------------------------------------------------------- equivalence


@pytest.mark.slow
@pytest.mark.parametrize("dataset", DATASETS)
def test_streamed_sample_by_sample_equals_batch(
    request: pytest.FixtureRequest, dataset: str
) -> None:
    trials = find_trials([dataset_root(request, dataset)])
    assert trials
    for folder in trials:
        trial = read_trial(folder)
        streamed = label_trial_streamed(trial)
        assert_same(label_trial(trial), streamed)
        seqs = sorted(
            w.seq for lv in streamed.words["R"].values() for ws in lv.values() for w in ws
        )
        assert seqs == list(range(1, len(seqs) + 1))  # every word numbered once, increasing


@pytest.mark.parametrize("dataset", DATASETS)
def test_push_many_equals_batch(request: pytest.FixtureRequest, dataset: str) -> None:
    for folder in find_trials([dataset_root(request, dataset)]):
        trial = read_trial(folder)
        assert_same(label_trial(trial), label_trial_streamed(trial, many=True))


@pytest.mark.parametrize("source", SOURCES)
def test_given_domains_release_moment_words_before_the_end(
    request: pytest.FixtureRequest, source: str
) -> None:
    (folder,) = trial_folders(request, source, ["20121127-HIROSA-S-01"], [0])
    trial = read_trial(folder)
    config = default_config()
    wrench = trial.wrench["R"]
    domains = {ax: axis_domain(wrench[:, AXES.index(ax)], config) for ax in config.domain_axes}
    stream = ArmStream(config, StreamConfig(moment_domains=domains))
    early: list[Word] = []
    for k in range(len(trial.time)):
        early += stream.push(trial.time[k], wrench[k])
    assert any(w.axis == "Mz" and w.level is Level.COMPOSITION for w in early)
    # without the domain, moment-axis words wait for finish() (the domain may still change)
    waiting = ArmStream(config)
    got = [w for k in range(len(trial.time)) for w in waiting.push(trial.time[k], wrench[k])]
    assert not any(w.axis in config.domain_axes for w in got)
    assert_same(
        label_trial(trial),
        label_trial_streamed(trial, stream_config=StreamConfig(moment_domains=domains)),
    )


@pytest.mark.shared_data
def test_label_engine_stream_reproduces_golden(hiro_data: Path, tmp_path: Path) -> None:
    folder = find_trials([hiro_data / "SIM_HIRO_ONE_SA_SUCCESS"])[0]
    assert main(["label", str(folder), "--out", str(tmp_path), "--engine", "stream"]) == 0
    for level in (Level.COMPOSITION, Level.BEHAVIOR):
        for axis in AXES:
            ours = read_words(level_path(tmp_path / folder.name, level, axis), level, axis)
            golden = read_words(level_path(folder / "golden", level, axis), level, axis)
            assert first_difference(ours, golden) is None


def test_label_engine_stream_writes_the_batch_files(sim_data: Path, tmp_path: Path) -> None:
    """On a generated trial, `rcbht label --engine stream` writes the batch engine's files."""
    folder = find_trials([sim_data / SIM_SUCCESS])[0]
    for engine in ("batch", "stream"):
        assert (
            main(["label", str(folder), "--out", str(tmp_path / engine), "--engine", engine]) == 0
        )
    for level in LEVELS:
        for axis in AXES:
            batch = level_path(tmp_path / "batch" / folder.name, level, axis)
            streamed = level_path(tmp_path / "stream" / folder.name, level, axis)
            assert streamed.read_text() == batch.read_text(), (level.value, axis)


def test_one_block_statistics_are_bit_identical_to_the_batch_ones() -> None:
    rng = np.random.default_rng(5)
    for m in (1, 3, 5):
        t = np.sort(rng.uniform(0, 100, (40, m)), axis=1)
        y = rng.normal(0, 10, (40, m, 6)) * rng.uniform(0, 1e3)
        many = block_stats(t, y)
        for k in range(40):
            one = block_stats_one(t[k].tolist(), y[k].tolist())
            assert one[0] == many[0]
            for field in (1, 2, 8):  # per block
                assert one[field][0] == many[field][k]
            for field in (3, 4, 5, 6, 7, 9):  # per axis and block
                assert [col[0] for col in one[field]] == [col[k] for col in many[field]]


# --------------------------------------------------------------------------- intake policies


def synthetic(n: int = 3000, seed: int = 0, rate: float = 200.0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    w = np.stack([np.sin(t * (a + 1)) * (3 + a) for a in range(6)], axis=1)
    return t, w + np.cumsum(rng.normal(0, 0.05, (n, 6)), axis=0)


def run(
    samples: list[tuple[float, object]], config: StreamConfig | None = None
) -> tuple[list, ArmStream]:
    stream = ArmStream(stream_config=config)
    out = stream.mark_boundary(0.0)
    out += [w for t, y in samples for w in stream.push(t, y)]
    out += stream.finish()
    return out, stream


def by_level(words: list[Word]) -> dict:
    groups: dict = {}
    for w in words:
        groups.setdefault((w.level, w.axis), []).append(key(w))
    return groups


def clean_samples() -> list[tuple[float, list[float]]]:
    t, w = synthetic()
    return [(float(t[k]), w[k].tolist()) for k in range(len(t))]


def test_nonfinite_components_hold_the_last_value_and_are_counted() -> None:
    samples = clean_samples()
    bad = [list(s) for s in samples]
    bad[500] = (bad[500][0], [math.nan, *bad[500][1][1:]])
    bad[900] = (bad[900][0], [*bad[900][1][:5], math.inf])
    words, stream = run(bad)
    assert stream.counters.nonfinite_samples == 2
    expected = [list(s) for s in samples]
    expected[500] = (expected[500][0], [samples[499][1][0], *samples[500][1][1:]])
    expected[900] = (expected[900][0], [*samples[900][1][:5], samples[899][1][5]])
    assert by_level(words) == by_level(run(expected)[0])
    assert all(math.isfinite(v) for w in words for v in w.features.values())


def test_nonfinite_drop_policy_equals_the_stream_without_the_sample() -> None:
    samples = clean_samples()
    bad = list(samples)
    bad[700] = (bad[700][0], [1.0, math.nan, 1.0, 1.0, 1.0, 1.0])
    config = StreamConfig(nonfinite="drop")
    words, stream = run(bad, config)
    assert stream.counters.nonfinite_samples == 1
    assert by_level(words) == by_level(run(samples[:700] + samples[701:], config)[0])


def test_duplicate_and_decreasing_stamps_are_dropped_and_counted() -> None:
    samples = clean_samples()
    noisy = [*samples[:1000], samples[999], samples[500], *samples[1000:]]
    words, stream = run(noisy)
    assert stream.counters.duplicate_stamps == 1
    assert stream.counters.decreasing_stamps == 1
    assert by_level(words) == by_level(run(samples)[0])


def test_gaps_are_counted_or_interpolated() -> None:
    samples = clean_samples()
    gapped = samples[:1000] + samples[1040:]
    words, stream = run(gapped)
    assert stream.counters.gaps == 1 and stream.counters.interpolated_samples == 0
    assert words
    filled, stream = run(gapped, StreamConfig(gap_policy="interpolate"))
    assert stream.counters.gaps == 1 and stream.counters.interpolated_samples == 40
    t0, y0 = samples[999]
    t1, y1 = samples[1040]
    fill = [(t0 + k * (t1 - t0) / 41, [a + k / 41 * (b - a) for a, b in zip(y0, y1, strict=True)])
            for k in range(1, 41)]  # fmt: skip
    assert by_level(filled) == by_level(run(samples[:1000] + fill + samples[1040:])[0])


def test_a_changed_rate_is_counted_once_and_adopted() -> None:
    t1, w1 = synthetic(1000, rate=200.0)
    t2 = t1[-1] + np.arange(1, 1001) / 100.0
    samples = [(float(t), w1[k].tolist()) for k, t in enumerate(t1)]
    samples += [(float(t), w1[k].tolist()) for k, t in enumerate(t2)]
    words, stream = run(samples)
    assert stream.counters.rate_changes == 1
    assert stream.counters.gaps == 0
    assert words


@pytest.mark.parametrize("bad", [[1.0, 2.0], "abcdef", None, [1, 2, 3, 4, 5, "x"]])
def test_malformed_samples_never_raise(bad: object) -> None:
    stream = ArmStream()
    assert stream.push(0.0, [0.0] * 6) == []
    assert stream.push(0.005, bad) == []  # type: ignore[arg-type]
    assert stream.push(float("nan"), [0.0] * 6) == []
    assert stream.counters.malformed_samples == 2
    stream.finish()
    assert stream.push(1.0, [0.0] * 6) == []  # after finish()
    assert stream.counters.malformed_samples == 3


def test_late_boundaries_are_counted() -> None:
    stream = ArmStream()
    for k in range(20):
        stream.push(k * 0.005, [0.0] * 6)
    stream.mark_boundary(0.01, "rotation")
    assert stream.counters.late_boundaries == 1
    for bad in (float("nan"), "soon", None):
        assert stream.mark_boundary(bad, "insertion") == []  # type: ignore[arg-type]
    assert stream.counters.malformed_boundaries == 3 and stream.ctx.boundaries == [0.01]


def test_a_bug_in_the_stream_raises_instead_of_being_counted(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Bad input is counted; a defect surfaces (rosbags' modules raise precise errors too)."""
    stream = ArmStream()

    def broken(*_: object) -> None:
        raise ZeroDivisionError("a defect")

    monkeypatch.setattr(stream, "_block", broken)
    with pytest.raises(ZeroDivisionError):
        for k in range(stream.window + 1):
            stream.push(k * 0.005, [0.0] * 6)


def test_stream_config_profiles_load() -> None:
    assert load_stream_config("reference") == StreamConfig()
    assert load_stream_config("causal").profile == "causal"


def test_causal_profile_streams_moment_words_without_waiting() -> None:
    t, w = synthetic(4000)
    w[:, 3:] *= 0.05  # small moments: the reference would wait for the trial's domain
    stream = ArmStream(stream_config=load_stream_config("causal"))
    got = [x for k in range(len(t)) for x in stream.push(t[k], w[k])]
    assert any(x.axis == "Mx" for x in got)
    trial = Trial("syn", t, {"R": w}, (0.0, 5.0, 10.0, 15.0))
    causal = label_trial_streamed(trial, stream_config=load_stream_config("causal"))
    assert all(causal.axis_words("R", level, axis) for level in LEVELS for axis in AXES)


# --------------------------------------------------------------------------- memory


@pytest.mark.slow
def test_one_hour_at_1khz_keeps_the_retained_state_bounded() -> None:
    rng = np.random.default_rng(0)
    stream = ArmStream()
    stream.mark_boundary(0.0)
    chunk = 20_000
    hour = 3600 * 1000
    retained: list[int] = []
    words = 0
    for k in range(0, hour, chunk):
        t = np.arange(k, k + chunk) / 1000.0
        w = np.stack([np.sin(2 * np.pi * t / (7 + a)) * (3 + a) + 0.5 * np.sin(2 * np.pi * t * (0.9 + 0.1 * a))
                      for a in range(6)], axis=1) + rng.normal(0, 0.002, (chunk, 6))  # fmt: skip
        if k == 60_000:
            words += len(stream.mark_boundary(t[0] - 0.0005, "rotation"))
        if k == 120_000:
            stream.mark_boundary(t[0] - 0.0005, "insertion")
            stream.mark_boundary(t[0] - 0.0004, "mating")
        words += len(stream.push_many(t, w))
        retained.append(sum(stream.retained().values()))
    first_ten_minutes = max(retained[: 600_000 // chunk])
    assert words > 10_000  # the stream kept emitting final words all hour
    assert max(retained) <= 2 * first_ten_minutes  # no growth with stream length
    state = stream.retained()
    assert state["waiting_segments"] == 0 and state["block_samples"] < stream.window

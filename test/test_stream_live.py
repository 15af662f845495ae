"""The `live` stream profile: every word final within finality_bound_s of its end, the same words
however the samples are chunked, and the bound as the only difference from `causal`."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import SOURCES, trial_folders
from test_stream import assert_same

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.hiro import read_trial
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.taxonomy.batch import label_trial
from rcbht_introspection.taxonomy.config import default_config
from rcbht_introspection.taxonomy.stream import (
    ArmStream,
    StreamConfig,
    label_trial_streamed,
    load_stream_config,
)
from rcbht_introspection.taxonomy.words import AXES, Level, TrialWords, Word

REAL_TRIALS = ["20121127-HIROSA-S-01", "20121127-HIROSA-S-17", "20121127-HIROSA-S-33"]
SIM_TRIALS = [0, 3, 6]


def _trials(request: pytest.FixtureRequest, source: str) -> list[Trial]:
    return [read_trial(f) for f in trial_folders(request, source, REAL_TRIALS, SIM_TRIALS)]


def _label_in_random_chunks(trial: Trial, sc: StreamConfig, seed: int) -> TrialWords:
    """push_many in chunks of 1-400 samples, each boundary marked before the first sample after it."""
    rng = np.random.default_rng(seed)
    stream = ArmStream(default_config(), sc, "R")
    t, w = trial.time, trial.wrench["R"]
    marks = list(trial.state_times)
    words: list[Word] = []
    k = 0
    while k < len(t):
        while marks and marks[0] < t[k]:
            words += stream.mark_boundary(marks.pop(0))
        stop = k + int(rng.integers(1, 400))
        if marks:  # a chunk never runs past the next boundary
            stop = min(stop, int(np.searchsorted(t, marks[0], side="right")))
        stop = max(stop, k + 1)
        words += stream.push_many(t[k:stop], w[k:stop])
        k = stop
    for s in marks:
        words += stream.mark_boundary(s)
    words += stream.finish()
    out = TrialWords(name=trial.name)
    for word in words:
        out.words.setdefault("R", {}).setdefault(word.level, {}).setdefault(word.axis, []).append(
            word
        )
    return out


def test_live_profile_loads_with_its_bound() -> None:
    live = load_stream_config("live")
    assert live.profile == "live" and live.finality_bound_s is not None
    assert 0 < live.finality_bound_s <= 2.0  # the target: final within 2 s
    assert load_stream_config("reference").finality_bound_s is None
    assert load_stream_config("causal").finality_bound_s is None


@pytest.mark.parametrize(
    ("profile", "bound", "message"),
    [
        ("live", "null", "the live profile needs a bound > 0"),
        ("live", "0.0", "the live profile needs a bound > 0"),
        ("causal", "1.0", "applies to the live profile only"),
    ],
)
def test_a_bound_without_the_live_profile_or_the_reverse_is_an_input_error(
    tmp_path: Path, profile: str, bound: str, message: str
) -> None:
    file = tmp_path / "stream.yaml"
    file.write_text(f"profiles:\n  mine:\n    profile: {profile}\n    finality_bound_s: {bound}\n")
    with pytest.raises(InputError, match=message) as error:
        load_stream_config("mine", file)
    assert "finality_bound_s" in str(error.value) and "stream.yaml" in str(error.value)


@pytest.mark.parametrize("source", SOURCES)
def test_live_words_do_not_depend_on_how_samples_are_chunked(
    request: pytest.FixtureRequest, source: str
) -> None:
    live = load_stream_config("live")
    for i, trial in enumerate(_trials(request, source)):
        one_by_one = label_trial_streamed(trial, stream_config=live)
        assert_same(one_by_one, label_trial_streamed(trial, stream_config=live, many=True))
        assert_same(one_by_one, label_trial(trial, stream_config=live))  # the batch engine
        assert_same(one_by_one, _label_in_random_chunks(trial, live, seed=i))


@pytest.mark.parametrize("source", SOURCES)
def test_every_live_word_is_final_within_the_bound(
    request: pytest.FixtureRequest, source: str
) -> None:
    live = load_stream_config("live")
    assert live.finality_bound_s is not None
    for trial in _trials(request, source):
        period = float(np.median(np.diff(trial.time)))
        slack = default_config().window * period + 1e-9  # expiry is checked once a window step
        stream = ArmStream(default_config(), live, "R")
        marks = list(trial.state_times)
        delays: dict[Level, list[float]] = {level: [] for level in Level}
        for k, tk in enumerate(trial.time):
            while marks and marks[0] < tk:
                for word in stream.mark_boundary(marks.pop(0)):
                    delays[word.level].append(trial.time[k - 1] - word.end)
            for word in stream.push(tk, trial.wrench["R"][k]):
                delays[word.level].append(tk - word.end)
        for word in stream.finish():
            delays[word.level].append(trial.time[-1] - word.end)
        for level, values in delays.items():
            assert values, (trial.name, level)
            assert max(values) <= live.finality_bound_s + slack, (trial.name, level, max(values))
        # the bound is what releases them: without it, most MCs and LLBs wait much longer
        assert max(delays[Level.BEHAVIOR]) > 0.5 * live.finality_bound_s


@pytest.mark.parametrize("source", SOURCES)
def test_an_unreachable_bound_gives_the_causal_words(
    request: pytest.FixtureRequest, source: str
) -> None:
    causal = load_stream_config("causal")
    endless = dataclasses.replace(load_stream_config("live"), finality_bound_s=1e9)
    for trial in _trials(request, source)[:2]:
        assert_same(
            label_trial_streamed(trial, stream_config=causal),
            label_trial_streamed(trial, stream_config=endless),
        )


@pytest.mark.parametrize("source", SOURCES)
def test_the_live_words_cover_the_trial_like_the_reference(
    request: pytest.FixtureRequest, source: str
) -> None:
    """Cutting a sequence loses no time: each axis's words still tile the trial in order."""
    live = load_stream_config("live")
    for trial in _trials(request, source)[:2]:
        ref, got = label_trial(trial), label_trial_streamed(trial, stream_config=live)
        for level in (Level.COMPOSITION, Level.BEHAVIOR):
            for axis in AXES:
                a, b = ref.axis_words("R", level, axis), got.axis_words("R", level, axis)
                assert b[0].start == pytest.approx(a[0].start)
                assert b[-1].end == pytest.approx(a[-1].end, abs=0.01)
                starts = [w.start for w in b]
                assert starts == sorted(starts)


def test_a_cut_keeps_the_trial_long_state_of_the_passes() -> None:
    """After a cut the fresh chain goes on where the old one was: a duration pass that stopped
    for good stays stopped, step 3's largest amplitude and the LLB time flag are kept."""
    from rcbht_introspection.taxonomy.ops import StreamContext
    from rcbht_introspection.taxonomy.pipeline import AxisPipeline

    pipe = AxisPipeline(StreamContext(default_config(), causal=True, bound=1.0))
    old_mc, old_llb = pipe._composition_chain(), pipe._behavior_chain()
    for op in old_mc.ops + old_llb.ops:
        if hasattr(op, "stopped"):
            op.stopped = True
        if hasattr(op, "cycle"):
            op.cycle.max_amp = 42.0
        if hasattr(op, "flag"):
            op.flag = True
    new_mc, new_llb = pipe._composition_chain(), pipe._behavior_chain()
    new_mc.resume(old_mc)
    new_llb.resume(old_llb)
    stopped = [op.stopped for op in new_mc.ops + new_llb.ops if hasattr(op, "stopped")]
    assert len(stopped) == 2 * 4 + 5 and all(stopped)  # steps 3 and 4 per MC cycle, LLB step 1
    assert {op.cycle.max_amp for op in new_mc.ops if hasattr(op, "cycle")} == {42.0}
    assert new_llb.ops[0].flag is True


@pytest.mark.parametrize("source", SOURCES)
def test_engine_samples_carry_the_live_words_and_golden_is_refused(
    request: pytest.FixtureRequest, source: str
) -> None:
    from rcbht_introspection.grammar.split import split_words
    from rcbht_introspection.learn.data import load_trials

    live = load_stream_config("live")
    folders = trial_folders(request, source, REAL_TRIALS[:1], SIM_TRIALS[:1])
    (loaded,) = load_trials(folders, "auto", stream=live)
    assert loaded.source == "engine"  # auto: golden files hold the reference words
    trial = read_trial(folders[0])
    expected = split_words(
        label_trial(trial, stream_config=live), trial.state_times, trial.end_time, trial.phase_names
    )
    for got, want in zip(loaded.samples, expected, strict=True):
        assert got.subtask == want.subtask
        assert_same(got.words, want.words)
    with pytest.raises(InputError, match="stream profile 'live'"):
        load_trials(folders, "golden", stream=live)


def test_evaluate_scores_the_live_words_and_live_windows(
    request: pytest.FixtureRequest, tmp_path: Path
) -> None:
    from conftest import SIM_SUCCESS, dataset_root

    from rcbht_introspection.cli import main

    out, live_yaml = tmp_path / "eval.json", tmp_path / "live.yaml"
    live_yaml.write_text("live_augment:\n  stream_profile: live\n  window_s: 0.0\n")
    code = main(["evaluate", str(dataset_root(request, SIM_SUCCESS)), "--stream-profile", "live",
                 "--permutations", "1", "--validation-trials", "2", "--no-variant", "--no-peers",
                 "--live-score", "--live-config", str(live_yaml),
                 "--json", str(out), "--no-progress"])  # fmt: skip
    assert code == 0
    result = json.loads(out.read_text())
    assert result["stream_profile"] == "live" and result["words"] == "auto"
    assert 0.0 <= result["steady_state_accuracy"]["mean"] <= 1.0
    # the windows are those of the given live config (live stream profile, no window mode)
    from rcbht_introspection.io.hiro import find_trials
    from rcbht_introspection.learn.live import load_live_config, trial_live_samples

    windows = trial_live_samples(
        find_trials([dataset_root(request, SIM_SUCCESS)]), load_live_config(live_yaml)
    )
    assert result["live_accuracy"]["n_windows"] == sum(map(len, windows.values())) > 0


def test_the_segmenter_node_parameters_select_the_live_profile(tmp_path: Path) -> None:
    from rcbht_introspection.configure.params import SegmenterConfig, load_node_config
    from rcbht_introspection.live.segmenter import arm_stream_factory

    params = tmp_path / "segmenter.yaml"
    params.write_text("segmenter_node:\n  ros__parameters:\n    stream_profile: live\n")
    cfg = load_node_config(SegmenterConfig, params)
    stream = arm_stream_factory(stream_profile=cfg.stream_profile)("R")
    assert stream.causal and stream.ctx.bound == load_stream_config("live").finality_bound_s
    params.write_text("segmenter_node:\n  ros__parameters:\n    stream_profile: quick\n")
    with pytest.raises(InputError, match="stream_profile"):
        load_node_config(SegmenterConfig, params)

"""The wrench summary beside the words: block means streamed == computed from the trial, the
words + wrench features blind to a constant bias, and a running belief that reads only its own
sub-task's evidence (on generated trials and the REAL HIRO ones)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import HIRO, SOURCES, generated_trials, require, trial_folders
from hypothesis import given, settings
from hypothesis import strategies as st

from rcbht_introspection.cli import main
from rcbht_introspection.grammar.encoding.wrench import wrench_features
from rcbht_introspection.grammar.split import window_sample
from rcbht_introspection.io.hiro import read_trial
from rcbht_introspection.learn.data import load_samples
from rcbht_introspection.learn.live import load_live_config, stream_factory
from rcbht_introspection.learn.models import train_model
from rcbht_introspection.live.belief import Belief, BeliefTracker
from rcbht_introspection.live.classifier import ClassifierSession, PhaseInput, WordsInput
from rcbht_introspection.live.replay import node_inputs, node_stream, stream_trial
from rcbht_introspection.live.state import StateFilter
from rcbht_introspection.summaries.blocks import (
    BLOCK_S,
    BlockMeans,
    WrenchBlock,
    WrenchTrack,
    trial_tracks,
)
from rcbht_introspection.taxonomy.words import TrialWords


@pytest.fixture(scope="module", params=SOURCES)
def case(request: pytest.FixtureRequest) -> dict:
    """A model of three trials (words + wrench, with its running head) and a held-out trial."""
    hiro = ["20121127-HIROSA-S-01", "20121127-HIROSA-S-02", "20121127-HIROSA-S-30",
            "20121127-HIROSA-S-41"]  # fmt: skip
    *train, test = trial_folders(request, request.param, hiro, [0, 1, 2, 5])
    model = train_model(load_samples(train, words="engine"))
    return {"model": model, "trial": read_trial(test)}


def test_streamed_blocks_equal_the_trials_blocks(case: dict) -> None:
    """The blocks the segmenter sends with its words are the blocks training computes."""
    trial = case["trial"]
    streamed = stream_trial(trial, stream_factory(load_live_config()))
    sent = streamed.wrench_tracks()["R"]
    offline = trial_tracks(trial)["R"]
    assert len(sent) == len(offline) > 0.9 * float(trial.time[-1]) / BLOCK_S
    assert np.array_equal(sent.ends[: len(sent)], offline.ends[: len(offline)])
    assert np.array_equal(sent.means[: len(sent)], offline.means[: len(offline)])
    # every batch carries only blocks that ended at or before its sample (known at that time)
    for step in streamed.steps:
        assert all(b.end <= step.t + 1e-12 for batch in step.batches for b in batch.wrench)


def test_a_block_closes_at_the_first_sample_past_it() -> None:
    means = BlockMeans(period=0.05)
    for t, fz in ((0.0, 1.0), (0.02, 3.0), (0.049, 5.0)):
        means.push(t, (0, 0, fz, 0, 0, 0))
    assert means.take() == []
    means.push(0.05, (0, 0, 9.0, 0, 0, 0))
    [block] = means.take()
    assert (block.end, block.samples, block.mean[2]) == (0.05, 3, 3.0)
    means.push(0.2, (0, 0, 0, 0, 0, 0))  # an empty block (0.1, 0.15] is skipped
    assert [b.end for b in means.take()] == [0.1]


@settings(max_examples=30, deadline=None)
@given(
    bias=st.lists(st.floats(-30, 30), min_size=6, max_size=6),
    start=st.floats(0.0, 1.5),
    length=st.floats(0.0, 1.5),
)
def test_wrench_features_ignore_a_constant_bias(
    bias: list[float], start: float, length: float
) -> None:
    """Relative to the block before the window, a constant sensor offset cancels."""
    rng = np.random.default_rng(7)
    time = np.arange(0, 3.0, 0.004)
    wrench = np.cumsum(rng.normal(size=(len(time), 6)), axis=0)

    def features(values: np.ndarray) -> np.ndarray:
        means = BlockMeans()
        for t, row in zip(time.tolist(), values.tolist(), strict=True):
            means.push(t, row)
        sample = window_sample(
            TrialWords("t"),
            start,
            start + length,
            wrench={"R": WrenchTrack.of_blocks(means.take())},
        )
        return wrench_features(sample, ("R",))

    plain, biased = features(wrench), features(wrench + np.asarray(bias))
    assert np.allclose(plain, biased, atol=1e-9)


def _running(beliefs: list[Belief], start: float) -> list[tuple[float, str, tuple[float, ...]]]:
    """(window end, sub-task, probabilities) of the running beliefs whose window starts at
    `start` (boundary mode: the sub-task that began there)."""
    return [
        (b.end, b.subtask, b.probabilities)
        for b in beliefs
        if not b.final and b.start == start and b.n_words
    ]


def test_boundary_belief_reads_only_its_own_subtask(case: dict) -> None:
    """The running belief of a sub-task is the same whatever sub-task events came before it:
    the earlier boundaries dropped, moved and renamed, the same words and wrench after it."""
    model, trial = case["model"], case["trial"]
    [streamed] = node_stream([trial], stream_factory(load_live_config()))
    inputs = node_inputs(streamed)
    phases = [x for x in inputs if isinstance(x, PhaseInput)]
    third = phases[2]  # insertion: after two boundaries (approach, rotation)
    names = model.task.subtasks
    spliced: list[WordsInput | PhaseInput] = []
    for item in inputs:
        if isinstance(item, PhaseInput) and item.time < third.time:
            if item is phases[0]:  # one boundary only before it, named after another sub-task
                spliced.append(replace(item, name=names[-1]))
            continue
        spliced.append(item)

    def beliefs(items: list[WordsInput | PhaseInput]) -> list[Belief]:
        session = ClassifierSession(BeliefTracker(model), StateFilter())
        return [b for item in items for b, _ in session.receive([item]).beliefs]

    plain, other = _running(beliefs(inputs), third.time), _running(beliefs(spliced), third.time)
    assert len(plain) > 5
    assert other == plain


def test_blocks_of_a_straggling_message_are_put_in_place() -> None:
    """A batch's first message on another topic may arrive after a later batch's blocks."""

    def block(end: float) -> WrenchBlock:
        return WrenchBlock(end, 1, (end, 0, 0, 0, 0, 0))

    track = WrenchTrack()
    track.extend([block(0.1), block(0.15)])
    track.extend([block(0.05)])
    assert track.ends[: len(track)].tolist() == [0.05, 0.1, 0.15]
    assert track.means[: len(track), 0].tolist() == [0.05, 0.1, 0.15]
    early = track.until(0.1)
    track.extend([block(0.2)])
    track.drop_before(0.16)
    assert early.ends[: len(early)].tolist() == [0.05, 0.1]  # a copy: later changes stay out
    # the origin is the earliest block ever given, also the straggler's, and survives pruning
    assert track.origin is not None and track.origin[0] == 0.05 and len(track) == 2
    assert early.origin is not None and early.origin[0] == 0.05
    assert WrenchTrack().origin is None and track.until(0.01).origin is None


def test_evaluate_train_scores_another_set_beside_minirocket(
    request: pytest.FixtureRequest, tmp_path: Path
) -> None:
    """`rcbht evaluate TEST --train TRAIN`: whole and prefix accuracy beside MiniRocket and
    duration, also when both sets hold a trial of the same name."""
    trials = generated_trials(request)
    out = tmp_path / "transfer.json"
    args = ["evaluate", *map(str, trials[5:7]), "--train", *map(str, trials[:5]),
            "--permutations", "2", "--json", str(out), "--no-progress"]  # fmt: skip
    assert main(args) == 0
    result = json.loads(out.read_text())
    assert result["protocol"] == "transfer" and result["n_test_trials"] == 2
    assert result["accuracy"]["n"] == 2 and 0.25 < result["accuracy"]["mean"] <= 1
    assert set(result["prefix_accuracy"]) == {"10%", "25%", "50%", "75%"}
    assert all(0 <= v["minirocket_baseline"] <= 1 for v in result["prefix_accuracy"].values())
    assert 0 < result["minirocket_baseline"]["trial_splits"]["mean"] <= 1
    same = ["evaluate", str(trials[0]), "--train", *map(str, trials[:3]), "--permutations", "1",
            "--json", str(out), "--no-progress"]  # fmt: skip
    assert main(same) == 0 and json.loads(out.read_text())["n_test_trials"] == 1


@pytest.mark.shared_data
@pytest.mark.slow
def test_a_sensor_offset_of_another_day_leaves_the_replayed_state(tmp_path: Path) -> None:
    """Real Baxter bags: a model of session_a, two bags of other days replayed through the
    nodes' sessions as recorded and with +-20 N added to Fz of every sample: the /task_state
    time_accuracy moves by at most 0.03 (docs/results-live.md has the four bags over DDS)."""
    from rcbht_introspection.learn.data import load_trials, read_any_trial
    from rcbht_introspection.learn.live import live_training
    from rcbht_introspection.live.replay import replay_beliefs, replay_summary
    from rcbht_introspection.live.segmenter import arm_stream_factory
    from rcbht_introspection.taxonomy.config import load_taxonomy_config

    baxter = HIRO.parent / "baxter_pick_and_place"
    require(baxter.is_dir(), f"Baxter bags not found at {baxter}")
    bags = [*sorted(baxter.glob("session_a/*.bag")), *(baxter / "other_sessions" / f"{n}.bag"
            for n in ("c0909_s09", "d0914_s01"))]  # fmt: skip
    phases = "0=-,1=approach,2=grasp,5=lift,3=transport,4=place"
    assert main(["bag", "import", *map(str, bags), "--out", str(tmp_path), "--wrench",
                 "/tag_multimodal.wrench_stamped", "--phase", "/tag_multimodal.tag",
                 "--phase-map", phases]) == 0  # fmt: skip
    day = sorted(tmp_path.glob("s??.mcap"))
    assert main(["calibrate", *map(str, day), "--out", str(tmp_path / "baxter.yaml")]) == 0
    taxonomy = load_taxonomy_config("baxter", tmp_path / "baxter.yaml")
    model, _ = live_training(load_trials(day, taxonomy=taxonomy), taxonomy=taxonomy)
    others = [read_any_trial(tmp_path / f"{n}.mcap") for n in ("c0909_s09", "d0914_s01")]
    accuracy = {}
    for bias in (0.0, 20.0, -20.0):
        shift = np.asarray([0.0, 0.0, bias, 0.0, 0.0, 0.0])
        trials = [replace(t, wrench={a: w + shift for a, w in t.wrench.items()}) for t in others]
        streamed = node_stream(trials, arm_stream_factory(taxonomy=taxonomy))
        replays = replay_beliefs(streamed, model, "boundary", 2.0, trials=trials)
        accuracy[bias] = replay_summary(replays, trials)["time_accuracy"]
    assert accuracy[0.0] >= 0.8, accuracy
    assert abs(accuracy[20.0] - accuracy[0.0]) <= 0.03, accuracy
    assert abs(accuracy[-20.0] - accuracy[0.0]) <= 0.03, accuracy

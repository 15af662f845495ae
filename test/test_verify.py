"""Verification core: live session == batch detector and offline namings, bias-robust features,
forest heads == scikit-learn, safe verifier file, conformal thresholds, session-grouped
calibration, the protocol's scoring rules, labels files, and detection of an injected anomaly."""

from __future__ import annotations

import dataclasses
import json
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest
from conftest import SIM_SUCCESS
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.ensemble import RandomForestClassifier
from sklearn.linear_model import LogisticRegression
from sklearn.preprocessing import StandardScaler

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.hiro import find_trials, read_trial
from rcbht_introspection.io.safe_file import read_safe_npz, write_safe_npz
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.learn.forest import ForestHead, check_packed
from rcbht_introspection.sim import load_sim_config, simulate_trial
from rcbht_introspection.summaries.windows import to_panel
from rcbht_introspection.verify.characterise import (
    FAILURE,
    Characteriser,
    RunningEvidence,
    _shared_by_signs,
    class_head,
    label_matrix,
    sign_table,
    span_index,
)
from rcbht_introspection.verify.config import VERIFIER_SIGNALS, load_verify_config
from rcbht_introspection.verify.detector import (
    Detection,
    Detector,
    calibration_folds,
    conformal_threshold,
)
from rcbht_introspection.verify.evaluate import GATE_S, RunResult, metrics
from rcbht_introspection.verify.evidence import EvidenceReader, Tick, named_at, namings, reader_of
from rcbht_introspection.verify.features import (
    departure_features,
    kind_columns,
    lag_ticks,
    trial_features,
)
from rcbht_introspection.verify.labels import DIRECTION_AXES, TrialLabel, label_of, read_labels
from rcbht_introspection.verify.model_file import VerifierModel, load_verifier, save_verifier
from rcbht_introspection.verify.monitor import NOMINAL, Verdict, VerifierSession
from rcbht_introspection.verify.shape import ShapeHead
from rcbht_introspection.verify.stream import offline_verdicts
from rcbht_introspection.verify.train import train_verifier

FAILURES = ("deviation_r+", "deviation_y-", "misalignment")


@pytest.fixture(scope="module")
def trials(sim_data: Path) -> list[Trial]:
    """The session's 8 simulated successes and three labelled failure trials."""
    successes = [read_trial(p) for p in find_trials([sim_data / SIM_SUCCESS])]
    config = load_sim_config()
    failed = [
        simulate_trial(config, 7000 + i, failure=f, name=f"F-{f}") for i, f in enumerate(FAILURES)
    ]
    return successes + failed


@pytest.fixture(scope="module")
def labels(trials: list[Trial]) -> dict[str, TrialLabel]:
    return {t.name: label_of(t) for t in trials}


@pytest.fixture(scope="module")
def trained(trials: list[Trial], labels: dict[str, TrialLabel]) -> VerifierModel:
    """A verifier trained on every trial (the tests that need no held-out trial share it)."""
    return train_verifier(trials, labels, load_verify_config())


@pytest.fixture(scope="module")
def held_out_model(
    trials: list[Trial], labels: dict[str, TrialLabel], tmp_path_factory: pytest.TempPathFactory
) -> VerifierModel:
    """A verifier without the first success and the last failure, saved and loaded. Its
    characteriser is fitted on many evidence rows (onsets every 2.5 s of the training trials,
    named by the sign of the latest span's Fz and Fy change), so its namings change as the
    evidence grows: three failures give too few rows for any tree to split. It reads every
    signal, so the live session is compared with the batch detector on each."""
    train = trials[1:-1]
    config = dataclasses.replace(load_verify_config(), signals=VERIFIER_SIGNALS)
    model = train_verifier(train, labels, config)
    reader = reader_of(model.detector, "wrench", 1)
    rows, windows, names = [], [], []
    for trial in train:
        tf = trial_features(trial, config)
        ticks = reader.ticks(tf)
        for onset in tf.times[5::50]:
            for r in namings(reader, config.evidence_s, float(onset), ticks, float(onset)):
                latest = 12 * len(config.evidence_s)  # the last span's block: the newest
                fz, fy = r.features[latest + 2], r.features[latest + 1]
                cls = "push" if fz > 0 else "pull"
                rows.append(r.features)
                windows.append(r.window)
                names.append(TrialLabel(trial.name, "failure", cls, None, (0.0, float(np.sign(fy)) * 1e-3, 0.0)))  # fmt: skip
    char = Characteriser(n_estimators=20, shape_weight=0.5)  # the shape head votes live too
    trials = [lb.trial for lb in names]
    model.characteriser = char.fit(np.vstack(rows), label_matrix(names), windows, trials)
    path = tmp_path_factory.mktemp("held_out") / "v.npz"
    return load_verifier(save_verifier(model, path))


def offline_namings(
    model: VerifierModel, trial: Trial, detection: Detection
) -> list[tuple[float, tuple[str, dict[str, float], dict[str, str]]]]:
    """The batch path's namings of a trial from its alarm on (evidence from its onset)."""
    assert model.characteriser is not None
    if detection.alarm is None or detection.onset is None:
        return []
    config = model.config
    tf = trial_features(trial, config)
    reader = reader_of(model.detector, "wrench", len(model.arms))
    ticks = reader.ticks(tf)
    rows = namings(reader, config.evidence_s, detection.onset, ticks, detection.alarm, config.lag_s)
    return [(r.time, model.characteriser.characterise(r.features, r.window)) for r in rows]


def assert_live_names_as_offline(
    model: VerifierModel,
    trial: Trial,
    verdicts: Sequence[Verdict],
    detection: Detection,
    varied: bool = True,
) -> int:
    """Tick for tick, the live verdicts' class, probabilities and directions are the offline
    naming standing at that tick (named_at); returns how many alarm verdicts were compared."""
    named = offline_namings(model, trial, detection)
    if varied:  # the namings change as the evidence grows
        assert len({str(n[1]) for _, n in named}) > 1
    classes = [(t, n[0]) for t, n in named]
    compared = 0
    for v in verdicts:
        if not v.alarm:
            assert v.failure_class == "" and v.health == NOMINAL
            continue
        want = named_at(classes, v.time)
        assert v.failure_class == want, v.time
        current = [n for t, n in named if t <= v.time + 1e-9][-1]
        assert v.class_probabilities == current[1] and v.directions == current[2]
        compared += 1
    return compared


def test_failure_labels_come_from_the_simulator(labels: dict[str, TrialLabel]) -> None:
    failed = [lb for lb in labels.values() if lb.failed]
    assert [lb.failure_class for lb in failed] == list(FAILURES)
    assert all(lb.onset is not None and lb.onset > 0 for lb in failed)
    assert failed[0].directions() == {"x": "0", "y": "0", "r": "+"}
    assert failed[1].directions() == {"x": "0", "y": "-", "r": "0"}
    misaligned = failed[2].directions()  # the housing's offset, as the part's against it
    assert misaligned is not None and misaligned["x"] == misaligned["r"] == "0"
    assert misaligned["y"] != "0"


def test_live_session_equals_the_batch_detector(
    trials: list[Trial], held_out_model: VerifierModel
) -> None:
    """Scores, alarm and onset as the batch detector gives them; from the alarm on, the class,
    its probabilities and the directions the offline namings give at that tick."""
    model = held_out_model
    config = model.config
    assert model.characteriser is not None
    alarmed = 0
    for trial in (trials[0], trials[-1]):
        tf = trial_features(trial, config)
        batch = model.detector.run(tf)
        verdicts = offline_verdicts(trial, model)
        assert [v.time for v in verdicts] == pytest.approx(list(tf.times), abs=1e-9)
        np.testing.assert_allclose([v.score for v in verdicts], batch.score, rtol=1e-12)
        assert verdicts[-1].alarm_time == batch.alarm
        assert verdicts[-1].onset == batch.onset
        if batch.alarm is not None:
            alarmed += 1
            assert assert_live_names_as_offline(model, trial, verdicts, batch) > 0
            assert verdicts[-1].health == verdicts[-1].failure_class != ""
        else:
            assert {v.health for v in verdicts} == {NOMINAL}
    assert alarmed, "the held-out failure must raise the alarm for this test"


def test_live_session_with_a_late_first_event_equals_the_batch_detector(
    trials: list[Trial], held_out_model: VerifierModel
) -> None:
    """A robot streams wrench before its state machine's first event: the ticks before it are
    judged 'no sub-task yet', and an alarm's evidence is named as offline."""
    config = held_out_model.config
    failing = trials[-1]
    late = dataclasses.replace(failing, state_times=(0.5, *failing.state_times[1:]))
    tf = trial_features(late, config)
    batch = held_out_model.detector.run(tf)
    verdicts = offline_verdicts(late, held_out_model)
    np.testing.assert_allclose([v.score for v in verdicts], batch.score, rtol=1e-12)
    assert verdicts[-1].alarm_time == batch.alarm and verdicts[-1].onset == batch.onset
    assert verdicts[0].phase == "" and verdicts[-1].phase != ""
    assert batch.alarm is not None
    assert assert_live_names_as_offline(held_out_model, late, verdicts, batch) > 0


def test_two_arms_with_offset_stamps_and_a_silent_arm_still_give_verdicts(
    trials: list[Trial], labels: dict[str, TrialLabel]
) -> None:
    some = [*trials[:4], *trials[-3:]]  # four successes, the three failures
    both = [dataclasses.replace(t, wrench={"L": t.wrench["R"], "R": t.wrench["R"]}) for t in some]
    model = train_verifier(both, labels, load_verify_config())
    trial = both[0]
    session = VerifierSession(model)
    session.phase(trial.phase_names[0], 0.0)
    time = np.asarray(trial.time) - float(trial.time[0])
    verdicts = []
    for i, t in enumerate(time[: len(time) // 2]):
        verdicts += session.push("R", float(t), trial.wrench["R"][i])
        if t < 2.0:  # the left arm's stamps run 5 ms late, then it falls silent
            verdicts += session.push("L", float(t) + 0.005, trial.wrench["L"][i])
    ticks = int(time[len(time) // 2 - 1] / model.config.step_s)
    assert len(verdicts) >= ticks - 25  # at most the 1 s of waiting for the silent arm behind
    assert session.held_rows > 0
    assert [v.time for v in verdicts] == sorted(v.time for v in verdicts)
    # both arms in full: the live session is the batch detector on two arms
    failing = both[-1]
    batch = model.detector.run(trial_features(failing, model.config))
    live = offline_verdicts(failing, model)
    np.testing.assert_allclose([v.score for v in live], batch.score, rtol=1e-12)
    assert live[-1].alarm_time == batch.alarm
    assert_live_names_as_offline(model, failing, live, batch, varied=False)


def test_live_session_with_a_contradiction_equals_the_batch_mismatch_rule(
    trials: list[Trial], held_out_model: VerifierModel
) -> None:
    """A contradicting final verdict raises the alarm at the first tick it is known, with the
    contradicted sub-task's start as onset; the live session and the batch rule agree, and the
    class named from then on is the offline naming of that evidence."""
    from rcbht_introspection.verify.mismatch import MISMATCH, Contradiction, with_mismatch

    model = held_out_model
    config = model.config
    nominal = trials[0]
    tf = trial_features(nominal, config)
    batch_plain = model.detector.run(tf)
    assert batch_plain.alarm is None, "the held-out success must be quiet for this test"
    start = float(tf.starts[0])  # the first sub-task: its start, 0.0, is the onset
    assert start == 0.0
    known = float(tf.starts[2]) + 0.3
    c = Contradiction(known, start, tf.phases[0], tf.phases[1], 0.95)
    batch = with_mismatch(batch_plain, [c], config)
    verdicts = offline_verdicts(nominal, model, [c])
    np.testing.assert_allclose([v.score for v in verdicts], batch.score, rtol=1e-12)
    assert batch.alarm_signal == MISMATCH and batch.onset == start
    assert verdicts[-1].alarm_time == batch.alarm == min(t for t in tf.times if t >= known - 1e-9)
    assert verdicts[-1].onset == start
    assert all(not v.alarm for v in verdicts if v.time < known - 1e-9)
    assert verdicts[-1].signals[MISMATCH] == pytest.approx(0.95 / config.mismatch_min_probability)
    assert assert_live_names_as_offline(model, nominal, verdicts, batch, varied=False) > 0


def test_contradictions_need_a_confident_final_verdict_on_a_commanded_subtask() -> None:
    from rcbht_introspection.live.belief import UNKNOWN, Belief
    from rcbht_introspection.verify.mismatch import contradiction_of

    def belief(subtask: str, p: float, final: bool = True, phase: str = "insertion") -> Belief:
        classes = (subtask, "insertion") if subtask != "insertion" else (subtask, "x")
        return Belief(subtask, classes, (p, 1.0 - p), 2.0, 5.0, "boundary", phase, final)

    c = contradiction_of(belief("rotation", 0.9), 6.5, 0.8)
    assert c is not None and (c.time, c.start, c.phase, c.subtask) == (
        6.5,
        2.0,
        "insertion",
        "rotation",
    )
    assert c.probability == pytest.approx(0.9)
    assert contradiction_of(belief("rotation", 0.8), 6.5, 0.8) is None  # not above
    assert contradiction_of(belief("rotation", 0.9, final=False), 6.5, 0.8) is None  # running
    assert contradiction_of(belief("insertion", 0.99), 6.5, 0.8) is None  # agrees
    assert contradiction_of(belief(UNKNOWN, 0.99), 6.5, 0.8) is None
    assert contradiction_of(belief("rotation", 0.9, phase=""), 6.5, 0.8) is None  # window mode
    # a model that does not know the commanded sub-task cannot contradict it
    unknown_phase = Belief("rotation", ("rotation", "x"), (0.9, 0.1), 2, 5, "boundary", "new", True)
    assert contradiction_of(unknown_phase, 6.5, 0.8) is None


def test_the_change_block_is_the_mean_minus_the_mean_lag_s_before(trials: list[Trial]) -> None:
    """change(t) = mean(t) - mean(t - lag_s), from the first tick while the stream is younger;
    a constant offset on every sample leaves the change as it was and shifts the mean by it."""
    config = load_verify_config()
    lag = lag_ticks(config)
    assert lag == round(config.lag_s / config.step_s) > 1
    trial = trials[-1]
    tf = trial_features(trial, config)
    mean, change = (
        tf.features[:, kind_columns("mean", 1)],
        tf.features[:, kind_columns("change", 1)],
    )
    assert np.all(np.diff(tf.times) > 0) and len(tf.times) > 3 * lag
    earlier = mean[np.maximum(np.arange(len(mean)) - lag, 0)]
    np.testing.assert_allclose(change, mean - earlier, rtol=0, atol=1e-9)
    assert np.all(change[0] == 0)
    assert np.abs(change).max() > 1.0  # the contacts do change the wrench
    offset = np.array([15.0, -4.0, 40.0, 0.5, -0.3, 0.2])
    shifted = dataclasses.replace(trial, wrench={"R": trial.wrench["R"] + offset})
    sf = trial_features(shifted, config)
    np.testing.assert_array_equal(sf.times, tf.times)
    np.testing.assert_allclose(sf.features[:, kind_columns("change", 1)], change, atol=1e-9)
    np.testing.assert_allclose(sf.features[:, kind_columns("mean", 1)], mean + offset, atol=1e-9)


def test_the_departure_is_the_mean_minus_its_level_lag_s_into_the_sub_task(
    trials: list[Trial],
) -> None:
    """departure(t) = mean(t) - mean at the sub-task's tick lag_s after its first, 0 before;
    the reference is the trial's own, so a constant offset leaves it as it was."""
    config = load_verify_config()
    lag = lag_ticks(config)
    trial = trials[-1]
    tf = trial_features(trial, config)
    mean_cols = kind_columns("mean", 1)
    dep = departure_features(tf, lag)
    np.testing.assert_array_equal(
        np.delete(dep.features, mean_cols, 1), np.delete(tf.features, mean_cols, 1)
    )
    for j in range(len(tf.phases)):
        ticks = np.flatnonzero(tf.phase_index == j)
        assert len(ticks) > lag, tf.phases[j]
        got = dep.features[ticks][:, mean_cols]
        assert np.all(got[:lag] == 0.0)
        want = tf.features[ticks[lag:]][:, mean_cols] - tf.features[ticks[lag], mean_cols]
        np.testing.assert_allclose(got[lag:], want, rtol=0, atol=1e-12)
    assert np.abs(dep.features[:, mean_cols]).max() > 1.0  # the contacts do move the wrench
    offset = np.array([15.0, -4.0, 40.0, 0.5, -0.3, 0.2])
    shifted = dataclasses.replace(trial, wrench={"R": trial.wrench["R"] + offset})
    moved = departure_features(trial_features(shifted, config), lag)
    np.testing.assert_allclose(moved.features[:, mean_cols], dep.features[:, mean_cols], atol=1e-9)


def test_calibration_folds_hold_out_whole_sessions() -> None:
    names = [f"t{i}" for i in range(11)]
    groups = {n: f"s{i % 4}" for i, n in enumerate(names[:10])}  # t10: no session named
    folds = calibration_folds(names, groups, 3, seed=2)
    assert len(folds) == 3 and sorted(i for f in folds for i in f) == list(range(11))
    for session in {*groups.values(), "t10"}:
        holding = [k for k, f in enumerate(folds) if any(groups.get(names[i], names[i]) == session for i in f)]  # fmt: skip
        assert len(holding) == 1, session  # a session is never split across folds
    assert calibration_folds(names, groups, 3, seed=2) == folds  # seeded
    assert len(calibration_folds(names, groups, 9, seed=0)) == 5  # no more folds than sessions
    single = calibration_folds(names, None, 20, seed=0)  # no sessions: one trial per fold
    assert sorted(i for f in single for i in f) == list(range(11)) and {len(f) for f in single} == {
        1
    }


def test_a_constant_bias_raises_no_alarm_the_raw_wrench_does(trials: list[Trial]) -> None:
    """Fitted on the successes of one session, tested on successes of another whose sensor
    reads 15 N more Fz and 0.5 N m more Mx: the verifier's signals are the unbiased runs' (it
    reads the change), the raw-wrench baseline alarms on every biased run."""
    config = load_verify_config()
    successes = [t for t in trials if "failure" not in t.metadata]
    train, test = successes[:5], successes[5:]
    feats = [trial_features(t, config) for t in train]
    detector = Detector.fit(feats, config)  # one session: the folds hold out single trials
    assert detector.calibration["folds"] == len(train)
    raw = Detector.fit(feats, config, signals=("wrench_global",))
    bias = np.array([0.0, 0.0, 15.0, 0.5, 0.0, 0.0])
    plain_alarms = biased_alarms = raw_alarms = 0
    for t in test:
        biased = dataclasses.replace(t, wrench={"R": t.wrench["R"] + bias})
        plain, shifted = (
            detector.run(trial_features(t, config)),
            detector.run(trial_features(biased, config)),
        )
        np.testing.assert_allclose(shifted.normalised, plain.normalised, atol=1e-6)
        plain_alarms += plain.alarm is not None
        biased_alarms += shifted.alarm is not None
        raw_alarms += raw.run(trial_features(biased, config)).alarm is not None
    assert biased_alarms <= plain_alarms
    assert raw_alarms == len(test)  # the test can fail: a bias the raw wrench cannot ignore


@pytest.fixture(scope="module")
def cell_successes() -> list[Trial]:
    """Ten successes of the repeated-program cell (config/sim/cell.yaml), whose nominal runs
    are alike, as a fixed robot program's are."""
    cell = load_sim_config(Path(__file__).resolve().parents[1] / "config" / "sim/cell.yaml")
    return [simulate_trial(cell, 500 + i, name=f"S-{i:02d}") for i in range(10)]


@pytest.mark.parametrize("after_s", [0.5, 1.0, 2.0])
def test_an_injected_contact_anomaly_raises_the_alarm_after_it(
    cell_successes: list[Trial], after_s: float
) -> None:
    config = load_verify_config()
    held = cell_successes[-1]
    detector = Detector.fit([trial_features(t, config) for t in cell_successes[:-1]], config)
    onset = float(held.state_times[1]) + after_s  # in rotation: the part presses on the housing
    plain = detector.run(trial_features(held, config))
    hit = detector.run(trial_features(_jammed(held, onset), config))
    assert hit.alarm is not None and onset <= hit.alarm <= onset + GATE_S
    assert hit.onset is not None and onset - config.step_s <= hit.onset <= hit.alarm
    assert plain.alarm is None


def test_a_success_the_others_do_not_explain_is_no_reference(cell_successes: list[Trial]) -> None:
    """One of the training successes carries a jam (a near-failure that still succeeded): it
    is scored in the calibration but compared with no run, so a held-out run jammed the same
    way still raises the alarm instead of matching it."""
    config = dataclasses.replace(load_verify_config(), false_alarm_rate=0.2)  # 1 of 9 may go
    odd = cell_successes[0]
    odd = _jammed(odd, float(odd.state_times[1]) + 1.0)
    train = [odd, *cell_successes[1:-1]]
    detector = Detector.fit([trial_features(t, config) for t in train], config)
    assert detector.calibration["unexplained"] == [odd.name]
    assert detector.models.neighbours is not None
    assert detector.models.neighbours.n_trials == len(train) - 1
    held = cell_successes[-1]
    onset = float(held.state_times[1]) + 1.0
    hit = detector.run(trial_features(_jammed(held, onset), config))
    assert hit.alarm is not None and onset <= hit.alarm <= onset + GATE_S


def test_near_failures_that_recur_stay_references(cell_successes: list[Trial]) -> None:
    """Two training successes jammed alike explain each other: neither is taken out of the
    references (what recurs among successes is nominal)."""
    config = dataclasses.replace(load_verify_config(), false_alarm_rate=0.2)
    pair = [_jammed(t, float(t.state_times[1]) + 1.0) for t in cell_successes[:2]]
    train = [*pair, *cell_successes[2:-1]]
    detector = Detector.fit([trial_features(t, config) for t in train], config)
    unexplained = detector.calibration["unexplained"]
    assert isinstance(unexplained, list)
    assert not {t.name for t in pair} & set(unexplained)


def _jammed(trial: Trial, onset: float) -> Trial:
    """The trial with a jam from `onset`: 30 N more push, wedged about 17 mm off-centre."""
    wrench = trial.wrench["R"].copy()
    after = np.asarray(trial.time) >= onset
    wrench[after, 2] += 30.0
    wrench[after, 4] += 0.5
    return dataclasses.replace(trial, wrench={"R": wrench})


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    onset_tick=st.integers(0, 59),
    offset=st.sampled_from([0.0, 0.013, -0.02]),
    alarm_after=st.integers(0, 30),
    lead=st.sampled_from([0.0, 0.75]),
)
def test_running_evidence_and_namings_are_the_span_summaries(
    seed: int, onset_tick: int, offset: float, alarm_after: int, lead: float
) -> None:
    """The evidence begun at the alarm and fed tick by tick is, at every tick, each span's mean
    of the vectors since onset minus the reference tick's (the last before onset - lead; a span
    not reached repeats the last reached one), their largest and smallest minus the reference,
    the context, then where the task stands at that tick; the class is named at the alarm, at
    each tick opening a span and at the last tick."""
    config = load_verify_config()
    spans = config.evidence_s
    rng = np.random.default_rng(seed)
    n, step = 60, config.step_s
    times = np.arange(n) * step
    vectors = rng.normal(0.0, 2.0, (n, 6))
    phases = ("insertion", "approach")  # the reader's order, not the trial's
    ticks = [
        Tick(float(g), "approach" if g < 1.0 else "insertion", float(g if g < 1.0 else g - 1.0), v)
        for g, v in zip(times, vectors, strict=True)
    ]
    reader = EvidenceReader("wrench", phases, 1)
    onset = max(float(times[onset_tick]) + offset, 0.0)
    first = int(np.searchsorted(times, onset - 1e-9, "left"))  # first tick at or after onset
    alarm = min(first + alarm_after, n - 1)
    if first >= n:
        return
    ref = [k for k in ticks if k.time < onset - lead - 1e-9] or ticks[:1]
    reference = ref[-1].vector
    context = np.concatenate([reference, [ticks[first].elapsed], [float(ticks[first].phase == p) for p in phases]])  # fmt: skip

    def direct(i: int) -> np.ndarray:
        k = np.array([span_index(spans, times[j] - onset) for j in range(first, i + 1)])
        assert np.all(k == np.array([sum(s < times[j] - onset - 1e-9 for s in spans) for j in range(first, i + 1)]))  # fmt: skip
        out, last = [], np.zeros(6)
        for s in range(len(spans) + 1):
            if np.any(k == s):
                last = vectors[first : i + 1][k == s].mean(axis=0) - reference
            out.append(last)
        seen = vectors[first : i + 1]
        now = [*(float(ticks[i].phase == p) for p in phases), ticks[i].elapsed, times[i] - onset]
        return np.concatenate([*out, seen.max(axis=0) - reference, seen.min(axis=0) - reference, context, now])  # fmt: skip

    evidence = reader.begin(spans, onset, ticks[: alarm + 1], lead)
    np.testing.assert_allclose(evidence.features(), direct(alarm), rtol=1e-12, atol=1e-12)
    opened = []
    for i in range(alarm + 1, n):
        if evidence.add(float(times[i]), vectors[i], reader.now(ticks[i], onset)):
            opened.append(float(times[i]))
        np.testing.assert_allclose(evidence.features(), direct(i), rtol=1e-12, atol=1e-12)
    named = namings(reader, spans, onset, ticks, float(times[alarm]), lead)
    want = [float(times[alarm]), *opened]
    if want[-1] != times[-1]:
        want.append(float(times[-1]))
    assert [r.time for r in named] == want
    for r in named:
        np.testing.assert_allclose(r.features, direct(round(r.time / step)), rtol=1e-12, atol=1e-12)
        seen = vectors[first : round(r.time / step) + 1]  # the shape head's window
        np.testing.assert_allclose(r.window, seen - reference, rtol=1e-12, atol=1e-12)
    spans_hit = {span_index(spans, t - onset) for t in opened}
    assert len(spans_hit) == len(opened)  # each naming after the alarm opens a new span


def test_running_evidence_counts_a_tick_in_the_span_it_closes() -> None:
    ev = RunningEvidence((0.1, 0.25), 1.0, np.zeros(1), np.array([7.0]))
    assert ev.add(1.0, np.array([1.0])) and not ev.add(1.1, np.array([3.0]))  # 0.1 closes span 0
    assert ev.add(1.15, np.array([5.0])) and ev.add(1.3, np.array([np.nan]))
    assert ev.features() == pytest.approx([2.0, 5.0, 0.0, 5.0, 0.0, 7.0])  # spans, high, low


@pytest.mark.parametrize("n_classes", [2, 3])
def test_forest_heads_predict_as_scikit_learn(n_classes: int) -> None:
    rng = np.random.default_rng(n_classes)
    X = rng.normal(size=(240, 5))
    score = X[:, 0] + 0.5 * X[:, 1] * X[:, 2] + rng.normal(0.0, 0.3, len(X))
    y = np.array(["a", "b", "c"])[
        np.digitize(score, np.quantile(score, [0.4, 0.7])[: n_classes - 1])
    ]
    params = {"n_estimators": 15, "min_samples_leaf": 2, "random_state": 4}
    ours = ForestHead(**params).fit(X, y)
    theirs = RandomForestClassifier(**params).fit(X, y)
    test = rng.normal(size=(100, 5)) * 1.5
    assert list(ours.classes_) == list(theirs.classes_) == ["a", "b", "c"][:n_classes]
    np.testing.assert_allclose(  # the leaves' class shares are stored as float32
        ours.predict_proba(test), theirs.predict_proba(test), rtol=0, atol=1e-6
    )
    assert list(ours.predict(test)) == list(theirs.predict(test))
    arrays = {**ours.arrays_, "n_features": np.array(ours.n_features_in_)}
    again = ForestHead.from_arrays(ours.get_params(), list(ours.classes_), arrays)
    np.testing.assert_array_equal(again.predict_proba(test), ours.predict_proba(test))


def test_packed_trees_refuse_tampered_arrays() -> None:
    rng = np.random.default_rng(1)
    X = rng.normal(size=(120, 3))
    model = ForestHead(n_estimators=3).fit(X, np.where(X[:, 0] > 0, "p", "n"))
    a = model.arrays_
    check_packed(a, 2, 3)
    inner = int(np.flatnonzero(~a["leaf"])[1])  # an inner node of the first tree, not its root

    def tampered(key: str, value: int) -> dict[str, np.ndarray]:
        out = {k: v.copy() for k, v in a.items()}
        out[key][inner] = value
        return out

    with pytest.raises(ValueError, match="left children do not point forward"):
        check_packed(tampered("left", inner - 1), 2, 3)  # a loop back up the tree
    with pytest.raises(ValueError, match="right children do not point forward"):
        check_packed(tampered("right", len(a["leaf"])), 2, 3)  # beyond the nodes
    with pytest.raises(ValueError, match="split on features the model does not read"):
        check_packed(tampered("feature", 3), 2, 3)
    with pytest.raises(ValueError, match="do not match the classes"):
        check_packed(a, 3, 3)
    with pytest.raises(ValueError, match="differ in length"):
        check_packed({**a, "threshold": a["threshold"][:-1]}, 2, 3)


def test_the_sign_table_ties_signs_to_a_class_only_when_unambiguous() -> None:
    def fail(cls: str, dev: tuple[float, float, float] | None) -> TrialLabel:
        return TrialLabel("t", "failure", cls, 1.0, dev)

    table = sign_table(
        label_matrix(
            [
                fail("slip_x", (0.002, 0.0, 0.0)),
                fail("slip_x", (0.003, 0.0, 0.0)),
                fail("slip_xy", (0.002, 0.002, 0.0)),
                fail("slip_xy", (0.002, -0.002, 0.0)),  # two sign patterns: not in the table
                fail("twist", (0.0, 0.0, 0.05)),
                fail("turn", (0.0, 0.0, 0.06)),  # the same signs as twist: neither is
                fail("jam", None),
                fail("half", (0.0, 0.002, 0.0)),
                fail("half", None),  # not every trial has a deviation
            ]
        )
    )
    assert table == {("+", "0", "0"): "slip_x"}


def _two_sided_characteriser() -> Characteriser:
    """A characteriser of `slip_x` (always +x) and `beside` (y + or -, by feature 1)."""
    rng = np.random.default_rng(0)
    rows, labels = [], []
    for k in range(40):
        side = 1.0 if k % 2 else -1.0
        cls, dev = ("slip_x", (0.002, 0.0, 0.0)) if k < 20 else ("beside", (0.0, side * 0.005, 0.0))
        rows.append([10.0 if cls == "slip_x" else 0.0, side if k >= 20 else 0.0, rng.normal()])
        labels.append(TrialLabel(f"t{k}", "failure", cls, 1.0, dev))
    return Characteriser(n_estimators=20, min_samples_leaf=1, compose=True).fit(
        np.array(rows), label_matrix(labels)
    )


def test_a_class_whose_deviations_change_sign_names_them_with_its_own_head() -> None:
    """A housing to either side (misalignment, y + or -): the general heads learn from the
    classes of one sign pattern only, the class's own y head names its side when it is named."""
    ch = _two_sided_characteriser()
    assert set(ch.heads_) == {FAILURE, *DIRECTION_AXES, class_head("y", "beside")}
    assert list(ch.heads_["y"].classes_) == ["0"]  # slip_x only: beside's signs vary
    for side, want in ((1.0, "+"), (-1.0, "-")):
        cls, _, dirs = ch.characterise(np.array([0.0, side, 0.0]))
        assert cls == "beside" and dirs["y"] == want
    assert ch.characterise(np.array([10.0, 0.0, 0.0]))[2] == {"x": "+", "y": "0", "r": "0"}


def test_a_verifier_file_keeps_the_heads_of_a_class(trained: VerifierModel, tmp_path: Path) -> None:
    ch = _two_sided_characteriser()
    model = dataclasses.replace(trained, characteriser=ch)
    loaded = load_verifier(save_verifier(model, tmp_path / "v.npz")).characteriser
    assert loaded is not None and set(loaded.heads_) == set(ch.heads_)
    for row in ([0.0, 1.0, 0.0], [0.0, -1.0, 0.3], [10.0, 0.0, 0.0]):
        assert loaded.characterise(np.array(row)) == ch.characterise(np.array(row))


def test_direction_signs_share_the_deviation_classes_mass() -> None:
    """The class head's probability of "one of the sign table's classes" is shared among them
    by the direction heads' belief in each one's signs; other classes keep theirs."""
    signs = {("0", "-", "+"): "dev_a", ("+", "0", "0"): "dev_b"}
    probs = {"dev_a": 0.5, "dev_b": 0.2, "jam": 0.3}
    sure_b = {"x": {"+": 0.9, "0": 0.1}, "y": {"0": 1.0}, "r": {"0": 1.0}}
    got = _shared_by_signs(probs, sure_b, signs)
    assert got["jam"] == 0.3 and sum(got.values()) == pytest.approx(1.0)
    assert got["dev_b"] == pytest.approx(0.7) and got["dev_a"] == pytest.approx(0.0)
    undecided = {"x": {"+": 0.5, "0": 0.5}, "y": {"-": 0.5, "0": 0.5}, "r": {"+": 0.5, "0": 0.5}}
    even = _shared_by_signs(probs, undecided, signs)
    assert even["dev_a"] == pytest.approx(0.7 * 0.125 / 0.25) == even["dev_b"]
    assert _shared_by_signs(probs, {a: {"-": 1.0} for a in "xyr"}, signs) == probs  # no belief


def test_the_characteriser_heads_and_composed_signs(
    trained: VerifierModel, labels: dict[str, TrialLabel]
) -> None:
    ch = trained.characteriser
    assert ch is not None
    assert set(ch.heads_) == {FAILURE, *DIRECTION_AXES}  # no class has two sign patterns
    assert list(ch.heads_[FAILURE].classes_) == sorted(FAILURES)
    # the one misalignment's housing offset shares deviation_y-'s signs or not
    misaligned = next(lb for lb in labels.values() if lb.failure_class == "misalignment")
    shared = (misaligned.directions() or {}).get("y") == "-"
    assert ch.signs_ == {
        ("0", "0", "+"): "deviation_r+",
        **({} if shared else {("0", "-", "0"): "deviation_y-"}),
    }
    assert list(ch.heads_["x"].classes_) == ["0"]  # every deviation here is 0 along x


def test_a_saved_verifier_names_what_the_trained_one_names(
    trials: list[Trial], trained: VerifierModel, tmp_path: Path
) -> None:
    loaded = load_verifier(save_verifier(trained, tmp_path / "v.npz"))
    assert loaded.characteriser is not None and trained.characteriser is not None
    assert loaded.arms == trained.arms and loaded.trained_on == trained.trained_on
    assert loaded.characteriser.signs_ == trained.characteriser.signs_
    np.testing.assert_array_equal(loaded.detector.thresholds, trained.detector.thresholds)
    config = trained.config
    reader = reader_of(trained.detector, "wrench", 1)
    rows = 0
    for trial in trials:
        tf = trial_features(trial, config)
        np.testing.assert_array_equal(
            loaded.detector.run(tf).normalised, trained.detector.run(tf).normalised
        )
        onset = float(tf.times[len(tf.times) // 2])
        for r in namings(reader, config.evidence_s, onset, reader.ticks(tf), onset):
            x, w = r.features, r.window
            named = loaded.characteriser.characterise(x, w)
            assert named == trained.characteriser.characterise(x, w)
            rows += 1
    assert rows > len(trials)
    assert offline_verdicts(trials[-1], loaded) == offline_verdicts(trials[-1], trained)


def test_verifier_file_refuses_tampering(trained: VerifierModel, tmp_path: Path) -> None:
    path = save_verifier(trained, tmp_path / "v.npz")
    original = path.read_bytes()
    bad = tmp_path / "bad.npz"
    header, arrays = read_safe_npz(path, "verifier")
    loaded = 0
    for k in range(1, 24):  # a flipped byte anywhere: zip structure, zlib stream or content
        data = bytearray(original)
        at = len(data) * k // 24
        data[at] ^= 0xFF
        bad.write_bytes(bytes(data))
        try:
            load_verifier(bad)
        except InputError:
            continue
        # loaded: only a byte the zip reader does not use (a local header's copy of a size)
        # may differ, the content must be the original's
        loaded += 1
        header_bad, arrays_bad = read_safe_npz(bad, "verifier")
        assert header_bad == header and arrays_bad.keys() == arrays.keys(), at
        for name, value in arrays.items():
            np.testing.assert_array_equal(arrays_bad[name], value, err_msg=f"byte {at}")
    assert loaded <= 2, f"{loaded} of 23 flipped bytes went unnoticed"
    with pytest.raises(InputError, match="not found"):
        load_verifier(tmp_path / "missing.npz")

    def refused(edited: dict[str, object], changed: dict[str, np.ndarray], match: str) -> None:
        write_safe_npz(bad, edited, changed)  # a consistent file: its checksum rewritten
        with pytest.raises(InputError, match=match) as err:
            load_verifier(bad)
        assert "\n" not in str(err.value)

    # an array changed under the old checksum
    thresholds = arrays["thresholds"] * 0.5
    np.savez(bad, header=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8), **{**arrays, "thresholds": thresholds})  # fmt: skip
    with pytest.raises(InputError, match="checksum mismatch"):
        load_verifier(bad)
    leaf = arrays["head.class.leaf"].copy()
    leaf[int(np.flatnonzero(leaf)[0])] = False  # a leaf made an inner node: children of 0
    refused(dict(header), {**arrays, "head.class.leaf": leaf}, "children do not point forward")
    roots = arrays["head.class.roots"].copy()
    roots[-1] = len(leaf)
    refused(dict(header), {**arrays, "head.class.roots": roots}, "roots lie outside the nodes")
    short = {k: v for k, v in arrays.items() if k != "head.y.value"}
    refused(dict(header), short, "head 'y' lacks value")
    edited = json.loads(json.dumps(header))
    edited["characteriser"]["signs"] = [["0", "-", "+", "no_such_class"]]
    refused(edited, arrays, "unknown class 'no_such_class'")
    edited = json.loads(json.dumps(header))
    edited["characteriser"]["signs"] = [["0", "?", "+", FAILURES[0]]]
    refused(edited, arrays, r"are not one of -, 0, \+ per axis")
    wrong = {**arrays, "thresholds": arrays["thresholds"][:, :-1]}
    refused(dict(header), wrong, "thresholds do not match the signals and sub-tasks")
    edited = json.loads(json.dumps(header))
    edited["config"]["lag_s"] = -1
    refused(edited, arrays, "field config.lag_s")


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(0, 100, allow_nan=False), min_size=1, max_size=200),
    st.floats(0.01, 0.5),
)
def test_conformal_threshold_bounds_the_exceedances(values: list[float], rate: float) -> None:
    thr = conformal_threshold(values, 1 - rate)
    above = sum(v > thr for v in values) / len(values)
    assert above <= rate
    assert thr in values


def _run(name: str, failed: bool, onset: float | None, alarm: float | None) -> RunResult:
    label = TrialLabel(name, "failure" if failed else "success", "jam" if failed else "", onset)
    return RunResult(
        trial=name,
        label=label,
        onset=onset,
        onset_source="label" if failed else "",
        run_score=2.0 if alarm is not None else 0.5,
        alarm=alarm,
        alarm_signal="wrench" if alarm is not None else "",
        onset_estimate=alarm,
        predicted_class="jam" if alarm is not None and failed else "",
        class_by_evidence={},
        class_given_onset="",
        directions={},
        directions_given_onset={},
        times=np.zeros(0),
        score=np.zeros(0),
        classes_over_time=[],
    )


def test_the_protocol_counts_alarms_by_the_one_second_gate() -> None:
    runs = [
        _run("ok", True, 5.0, 5.4),  # within the gate: true positive
        _run("early", True, 5.0, 4.9),  # before onset: a false alarm, and missed
        _run("late", True, 5.0, 5.0 + GATE_S + 0.05),  # after the gate: missed
        _run("quiet", True, 5.0, None),
        _run("n1", False, None, None),
        _run("n2", False, None, 3.0),  # alarm on a nominal run: false positive
    ]
    m = metrics(runs)
    assert m["precision"] == pytest.approx(1 / 3)
    assert m["recall"] == pytest.approx(1 / 4)
    assert m["detection_accuracy"] == pytest.approx(2 / 6)
    assert m["false_alarms_per_nominal_run"] == pytest.approx(1 / 2)
    assert m["early_alarms"] == 1 and m["late_or_missed"] == 2
    assert m["detection_delay_s"]["p50"] == pytest.approx(0.4)


HEADER = "trial,outcome,failure_class,onset_s,dev_x_mm,dev_y_mm,dev_yaw_deg"


def test_labels_file(tmp_path: Path) -> None:
    path = tmp_path / "labels.csv"
    path.write_text(f"{HEADER}\na,failure,slip,12.5,2,,-3\nb,success,,,,,\n")
    got = read_labels(path)
    assert got["a"].onset == 12.5 and got["a"].directions() == {"x": "+", "y": "0", "r": "-"}
    assert not got["b"].failed and got["a"].session == got["b"].session == ""
    path.write_text(f"{HEADER}\nc,failure,slip,soon,,,\n")
    with pytest.raises(InputError) as err:
        read_labels(path)
    assert "line 2" in str(err.value) and "onset_s" in str(err.value)


def test_labels_file_reads_the_session_column_and_names_the_accepted_headers(
    tmp_path: Path,
) -> None:
    path = tmp_path / "labels.csv"
    path.write_text(f"{HEADER},session\na,failure,slip,1.5,,,,day2\nb,success,,,,,, day1 \nc,success,,,,,,\n")  # fmt: skip
    got = read_labels(path)
    assert {n: lb.session for n, lb in got.items()} == {"a": "day2", "b": "day1", "c": ""}
    path.write_text(f"{HEADER},session\na,failure,slip,1.5,,,\n")
    with pytest.raises(InputError, match=r"line 2.*expected 8 cells, got 7"):
        read_labels(path)
    for wrong in (HEADER.replace("onset_s", "onset"), f"{HEADER},day", "trial,outcome"):
        path.write_text(f"{wrong}\n")
        with pytest.raises(InputError) as err:
            read_labels(path)
        assert f"header must be {HEADER}[,session]" in str(err.value) and "line 1" in str(err.value)


def test_sessions_of_the_labels_group_the_calibration(
    trials: list[Trial], labels: dict[str, TrialLabel]
) -> None:
    """Two sessions named: two calibration folds, each holding out one session."""
    sessions = {n: dataclasses.replace(lb, session=f"s{i % 2}") for i, (n, lb) in enumerate(labels.items())}  # fmt: skip
    successes = [t for t in trials if not sessions[t.name].failed]
    model = train_verifier(successes, sessions, load_verify_config())
    assert model.trained_on["sessions"] == 2
    assert model.detector.calibration["folds"] == 2
    assert model.detector.calibration["grouped_by_session"] is True


def test_labels_file_refuses_bad_text_and_accepts_a_byte_order_mark(tmp_path: Path) -> None:
    header = HEADER + "\n"
    path = tmp_path / "labels.csv"
    path.write_text("\ufeff" + header + "a,failure,slip,1.5,,,\n", encoding="utf-8")
    assert read_labels(path)["a"].onset == 1.5
    path.write_bytes(b"\xff\xfe" + header.encode("utf-16-le"))
    with pytest.raises(InputError, match="not UTF-8"):
        read_labels(path)
    path.write_text(header + "a,failure,slip,-3,,,\n")
    with pytest.raises(InputError, match="onset_s"):
        read_labels(path)


def test_a_labels_row_naming_no_trial_is_an_error_when_strict(
    trials: list[Trial], tmp_path: Path
) -> None:
    """With --strict; without it the row is counted and warned about (test_bad_input.py)."""
    from rcbht_introspection.cli import main
    from rcbht_introspection.io.hiro import write_trial

    for t in trials[:4]:
        write_trial(t, tmp_path / "set" / t.name)
    labels = tmp_path / "labels.csv"
    labels.write_text(f"{HEADER}\n{trials[0].name}x,failure,slip,,,,\n")
    args = ["verify-train", str(tmp_path / "set"), "--labels", str(labels), "--out", "v.npz"]
    assert main([*args, "--strict"]) == 2


def _write_set(trials: list[Trial], folder: Path) -> Path:
    from rcbht_introspection.io.hiro import write_trial

    for t in trials:
        written = write_trial(t, folder / t.name)
        if "failure" in t.metadata:
            (written / "meta.json").write_text(json.dumps(t.metadata))
    return folder


def test_verify_eval_cli_reports_the_verifier_beside_the_baselines_and_anchors(
    trials: list[Trial], tmp_path: Path
) -> None:
    from rcbht_introspection.cli import main

    data = _write_set(trials, tmp_path / "set")
    out = tmp_path / "v.json"
    assert main(["verify-eval", str(data), "--folds", "2", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert set(result["baselines"]) == {"raw_wrench", "timing", "hmm", "minirocket"}
    for m in (result, *result["baselines"].values()):
        assert 0 <= m["roc_auc"] <= 1 and 0 <= m["false_alarms_per_nominal_run"] <= 1
        assert m["failure_runs"] == len(FAILURES) and m["nominal_runs"] == len(trials) - 3
        assert m["class_accuracy"] is not None
    assert result["protocol"]["onset_source"] == {"label": len(FAILURES)}
    assert "verifier_mismatch" not in result  # no classifier given
    runs = {m: {r["trial"]: r for r in result["records"] if r["method"] == m} for m in ("verifier", "minirocket")}  # fmt: skip
    for name, run in runs["verifier"].items():  # minirocket names on the verifier's alarms
        assert runs["minirocket"][name]["alarm"] == run["alarm"]


def test_verify_eval_cli_adds_the_mismatch_signal_with_a_classifier(
    trials: list[Trial], tmp_path: Path
) -> None:
    """With a sub-task classifier (trained on other trials): the verifier with the mismatch
    signal too, on the same runs; it can only add alarms to the verifier's."""
    from rcbht_introspection.cli import main

    data = _write_set(trials, tmp_path / "set")
    model = tmp_path / "cls.rcbht"
    successes = _write_set(trials[:4], tmp_path / "successes")
    assert main(["train", str(successes), "--out", str(model)]) == 0
    out = tmp_path / "v.json"
    args = ["verify-eval", str(data), "--folds", "2", "--model", str(model), "--no-peers"]
    assert main([*args, "--json", str(out)]) == 0
    with_model = json.loads(out.read_text())
    assert set(with_model["baselines"]) == {"raw_wrench", "timing"}
    both = with_model["verifier_mismatch"]
    verifier_runs = [r for r in with_model["records"] if r["method"] == "verifier"]
    assert both["runs"] == len(verifier_runs) == len(trials) and 0 <= both["roc_auc"] <= 1
    alarms = {m: {r["trial"]: r["alarm"] for r in with_model["records"] if r["method"] == m} for m in ("verifier", "verifier_mismatch")}  # fmt: skip
    for name, alarm in alarms["verifier"].items():
        if alarm is not None:
            assert alarms["verifier_mismatch"][name] is not None
            assert alarms["verifier_mismatch"][name] <= alarm


def test_verify_eval_gives_the_same_json_on_joblib_workers_and_a_dask_cluster(
    trials: list[Trial], tmp_path: Path
) -> None:
    """--jobs 2 (loky processes) and --scheduler (a loopback dask.distributed LocalCluster)
    write the sequential run's JSON byte for byte."""
    from dask.distributed import LocalCluster

    from rcbht_introspection.cli import main

    data = _write_set(trials, tmp_path / "set")
    args = ["verify-eval", str(data), "--folds", "2", "--no-peers", "--json"]
    assert main([*args, str(tmp_path / "seq.json")]) == 0
    assert main([*args, str(tmp_path / "jobs.json"), "--jobs", "2"]) == 0
    with LocalCluster(
        n_workers=2, threads_per_worker=1, host="127.0.0.1", dashboard_address=None
    ) as cluster:
        assert main([*args, str(tmp_path / "dask.json"), "--scheduler", cluster.scheduler_address]) == 0  # fmt: skip
    sequential = (tmp_path / "seq.json").read_text()
    assert json.loads(sequential)["records"]  # the per-run records are compared too
    assert (tmp_path / "jobs.json").read_text() == sequential
    assert (tmp_path / "dask.json").read_text() == sequential


def test_verify_eval_names_an_unreachable_scheduler(
    trials: list[Trial], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import dask

    from rcbht_introspection.cli import main

    data = _write_set(trials, tmp_path / "set")
    args = ["verify-eval", str(data), "--no-peers", "--scheduler", "tcp://127.0.0.1:9"]
    with dask.config.set({"distributed.comm.timeouts.connect": "2s"}):
        assert main(args) != 0
    assert "error: --scheduler tcp://127.0.0.1:9: " in capsys.readouterr().err


def _shaped(n: int, seed: int, informative: bool) -> tuple[list[np.ndarray], list[str]]:
    """Evidence windows of three classes: a rise, a fall or a bump on channel 0 (noise only
    when not `informative`), of various lengths."""
    rng = np.random.default_rng(seed)
    windows, y = [], []
    for i in range(n):
        k = i % 3
        ticks = int(rng.integers(12, 40))
        t = np.linspace(0.0, 1.0, ticks)
        curve = (t, -t, np.sin(np.pi * t))[k] if informative else np.zeros(ticks)
        w = rng.normal(0.0, 0.2, (ticks, 4))
        w[:, 0] += 3.0 * curve
        windows.append(w)
        y.append(f"class{k}")
    return windows, y


@pytest.mark.parametrize("n_classes", [2, 3])
def test_the_shape_head_gives_scikit_learns_probabilities_and_reloads(n_classes: int) -> None:
    windows, y = _shaped(60, 5, True)
    keep = [i for i, c in enumerate(y) if int(c[-1]) < n_classes]
    windows, y = [windows[i] for i in keep], [y[i] for i in keep]
    head = ShapeHead(n_kernels=200, n_points=32).fit(windows, y)
    features = head.transform_.transform(to_panel(windows, head.n_points))
    reference = LogisticRegression(C=head.C, max_iter=300)
    reference.fit(StandardScaler().fit_transform(features), y)  # the same fit, by scikit-learn
    scaled = (features - head.mean_) / head.scale_
    np.testing.assert_allclose(
        head.predict_proba(windows), reference.predict_proba(scaled), atol=1e-9
    )
    assert list(head.classes_) == list(reference.classes_)
    assert np.mean(head.classes_[head.predict_proba(windows).argmax(axis=1)] == np.array(y)) > 0.9
    again = ShapeHead.from_arrays(head.get_params(), list(head.classes_), head.to_arrays())
    np.testing.assert_array_equal(again.predict_proba(windows), head.predict_proba(windows))


@pytest.mark.parametrize("shape_informs", [True, False])
def test_the_shape_head_votes_only_when_it_helps_on_held_out_trials(shape_informs: bool) -> None:
    """The learnt weight: > 0 when only the windows tell the classes apart, 0 when only the
    forest's rows do."""
    windows, y = _shaped(90, 7, shape_informs)
    rng = np.random.default_rng(8)
    X = rng.normal(size=(len(y), 5))
    if not shape_informs:
        X[:, 0] += 3.0 * np.array([int(c[-1]) for c in y])
    labels = [TrialLabel(f"t{i // 3}", "failure", c) for i, c in enumerate(y)]
    groups = [lb.trial for lb in labels]
    char = Characteriser(n_estimators=30).fit(
        X, [lb.failure_class for lb in labels], windows, groups
    )
    if shape_informs:
        assert char.shape_ is not None and char.shape_weight_ > 0
        assert char.characterise(X[0], windows[0])[0] == y[0]
        assert char.predict(X[:1], windows[:1])[0] == y[0]
    else:
        assert char.shape_ is None and char.shape_weight_ == 0


def test_a_saved_shape_head_names_as_before_and_refuses_tampering(
    held_out_model: VerifierModel, tmp_path: Path
) -> None:
    """held_out_model went through save and load with its shape head (weight 0.5)."""
    ch = held_out_model.characteriser
    assert ch is not None and ch.shape_ is not None and ch.shape_weight_ == 0.5
    path = save_verifier(held_out_model, tmp_path / "v.npz")
    header, arrays = read_safe_npz(path, "verifier")
    window = np.random.default_rng(0).normal(size=(15, 12))
    again = load_verifier(path).characteriser
    assert again is not None and again.shape_ is not None
    np.testing.assert_array_equal(
        again.shape_.predict_proba([window]), ch.shape_.predict_proba([window])
    )
    bad = tmp_path / "bad.npz"
    for edit, match in (
        (lambda h, a: h["characteriser"]["shape"].update(weight=0.0), "weight 0.0 is not in"),
        (
            lambda h, a: a.update({"shape.coef": a["shape.coef"][:, :-1]}),
            "do not match its features",
        ),
        (lambda h, a: a.pop("shape.biases"), "biases"),
    ):
        h, a = json.loads(json.dumps(header)), dict(arrays)
        edit(h, a)
        write_safe_npz(bad, h, a)
        with pytest.raises(InputError, match=match):
            load_verifier(bad)


def test_the_shape_head_reads_a_flat_window_without_a_warning() -> None:
    """A few ticks since onset barely vary on some channel (here by 1e-9): aeon would warn on
    every naming."""
    windows, y = _shaped(30, 9, True)
    flat = np.zeros((3, 4))
    flat[1, 0] = 1e-9
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        head = ShapeHead(n_kernels=200, n_points=32).fit([*windows, flat], [*y, y[0]])
        proba = head.predict_proba([flat, np.ones((2, 4))])
    np.testing.assert_allclose(proba.sum(axis=1), 1.0)

"""Verification core: live session == batch detector, safe verifier file, conformal thresholds,
the protocol's scoring rules, labels files, and detection of an injected contact anomaly."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import SIM_SUCCESS
from hypothesis import given, settings
from hypothesis import strategies as st

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.hiro import find_trials, read_trial
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.learn.model_file import read_safe_npz, write_safe_npz
from rcbht_introspection.sim import load_sim_config, simulate_trial
from rcbht_introspection.verify.characterise import (
    FAILURE,
    Characteriser,
    EvidenceTick,
    ForestHead,
    RunningEvidence,
    channel_columns,
    contact_geometry,
    evidence_features,
    sign_table,
    wrench_means,
)
from rcbht_introspection.verify.config import CHARACTERISER_HEADS, KINDS, load_verify_config
from rcbht_introspection.verify.detector import Detector, conformal_threshold
from rcbht_introspection.verify.evaluate import GATE_S, RunResult, metrics
from rcbht_introspection.verify.features import TrialFeatures, feature_names, trial_features
from rcbht_introspection.verify.labels import DIRECTION_AXES, TrialLabel, label_of, read_labels
from rcbht_introspection.verify.model_file import load_verifier, save_verifier
from rcbht_introspection.verify.monitor import NOMINAL, VerifierSession
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


def test_failure_labels_come_from_the_simulator(labels: dict[str, TrialLabel]) -> None:
    failed = [lb for lb in labels.values() if lb.failed]
    assert [lb.failure_class for lb in failed] == list(FAILURES)
    assert all(lb.onset is not None and lb.onset > 0 for lb in failed)
    assert failed[0].directions() == {"x": "0", "y": "0", "r": "+"}
    assert failed[1].directions() == {"x": "0", "y": "-", "r": "0"}
    assert failed[2].directions() is None


def test_live_session_equals_the_batch_detector(
    trials: list[Trial], labels: dict[str, TrialLabel], tmp_path: Path
) -> None:
    config = load_verify_config()
    train = [t for t in trials if t.name not in (trials[0].name, trials[-1].name)]
    model = load_verifier(save_verifier(train_verifier(train, labels, config), tmp_path / "v.npz"))
    assert model.characteriser is not None
    for trial in (trials[0], trials[-1]):
        tf = trial_features(trial, config)
        batch = model.detector.run(tf)
        verdicts = offline_verdicts(trial, model)
        assert [v.time for v in verdicts] == pytest.approx(list(tf.times), abs=1e-9)
        np.testing.assert_allclose([v.score for v in verdicts], batch.score, rtol=1e-12)
        assert verdicts[-1].alarm_time == batch.alarm
        assert verdicts[-1].onset == batch.onset
        if batch.alarm is not None and batch.onset is not None:
            z = model.detector.models.envelope.z(tf)  # type: ignore[union-attr]
            means = wrench_means(tf)
            for v in verdicts[:: max(1, len(verdicts) // 25)] + verdicts[-1:]:
                if v.alarm:  # every head, contact forests included, as the batch path names it
                    cls, probs, dirs = model.characteriser.predict(
                        tf, z, batch.onset, v.time, means
                    )
                    assert (v.failure_class, v.directions) == (cls, dirs)
                    assert v.class_probabilities == pytest.approx(probs)
            assert verdicts[-1].health == verdicts[-1].failure_class
        else:
            assert {v.health for v in verdicts} == {NOMINAL}


def test_a_saved_characteriser_names_what_the_trained_one_names(
    trials: list[Trial], labels: dict[str, TrialLabel], tmp_path: Path
) -> None:
    config = load_verify_config()
    trained = train_verifier(trials, labels, config)
    loaded = load_verifier(save_verifier(trained, tmp_path / "v.npz"))
    assert trained.characteriser is not None and loaded.characteriser is not None
    assert set(loaded.characteriser.directions) == {"x", "y", "r"}
    # x is '0' for both deviations here: one class, so no contact forest for it
    assert set(loaded.characteriser.contact) == {"class", "y"}
    assert set(loaded.characteriser.narrow) == set(config.direction_channels) == {"x", "r"}
    assert loaded.characteriser.signs == trained.characteriser.signs
    envelope = trained.detector.models.envelope
    assert envelope is not None
    for trial in trials:
        tf = trial_features(trial, config)
        z = envelope.z(tf)
        onset = float(tf.times[len(tf.times) // 2])
        want = trained.characteriser.predict(tf, z, onset, tf.end, wrench_means(tf))
        got = loaded.characteriser.predict(tf, z, onset, tf.end, wrench_means(tf))
        assert got[0] == want[0] and got[2] == want[2]
        assert got[1] == pytest.approx(want[1], abs=1e-12)


def test_contact_geometry_reads_where_the_part_touched() -> None:
    """A 5 N push with 0.5 N along x at (3, -2) mm, from onset, over a constant sensor bias:
    the contact point, the yaw moment per pressing force and the force shares come back; before onset, nothing."""
    config = load_verify_config()
    times = np.arange(0.0, 2.0, config.step_s)
    bias = np.array([0.3, -0.2, 1.0, 0.01, -0.02, 0.005])
    force, point = np.array([0.5, 0.0, 5.0]), np.array([0.003, -0.002, 0.0])
    arm = np.tile(bias, (len(times), 1))
    arm[times >= 1.0] += np.concatenate([force, np.cross(point, force)])
    still = np.tile(bias, (len(times), 1))
    means = np.hstack([arm, still])  # two arms: the second never touches
    got = contact_geometry(times, means, 1.0, 2.0, config)
    assert got == pytest.approx([-2.0, 3.0, 0.2, 10.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], abs=1e-9)
    assert contact_geometry(times, means, 0.3, 0.9, config) is None
    # what comes after contact_s, and a tick pressing no more than RATIO_MIN_FORCE, do not count
    later = means.copy()
    later[times > 1.0 + config.contact_s + 1e-9, 0] += 3.0
    later[np.isclose(times, 1.0), :6] = bias + np.array([5.0, 0.0, 0.5, 0.0, 0.0, 0.0])
    assert contact_geometry(times, later, 1.0, 2.0, config) == pytest.approx(got, abs=1e-9)
    # a lever over a weak push is clipped
    weak = np.tile(bias, (len(times), 1))
    weak[times >= 1.0] += [0.0, 0.0, 1.5, -1.0, 0.0, 0.0]
    clipped = contact_geometry(times, weak, 1.0, 2.0, config)
    assert clipped is not None and clipped[0] == pytest.approx(-30.0)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    onset_tick=st.integers(0, 59),
    offset=st.sampled_from([0.0, 0.013, -0.02]),
    alarm_tick=st.integers(0, 59),
    first_kept=st.integers(0, 59),
)
def test_running_evidence_is_the_evidence_of_the_whole_span(
    seed: int, onset_tick: int, offset: float, alarm_tick: int, first_kept: int
) -> None:
    """The live verifier's running evidence, begun at the alarm from the ticks kept and fed one
    tick at a time, gives the batch `evidence_features` and `contact_geometry` bit for bit, as
    long as the kept ticks reach back to the reference tick (onsets between ticks too)."""
    config = load_verify_config()
    rng = np.random.default_rng(seed)
    n = 60
    times = np.arange(n) * config.step_s
    z = rng.normal(0.0, 40.0, (n, 9))
    z[rng.random(z.shape) < 0.1] = np.nan
    means = rng.normal(0.0, 2.0, (n, 12))  # two arms
    means[:, 2] += np.where(times > 1.5, 5.0, 0.0)  # the first arm presses from 1.5 s
    index = np.where(times < 1.0, 0, 1)
    starts = np.array([0.0, 1.0])
    tf = TrialFeatures(
        trial="t",
        phases=("approach", "insertion"),
        starts=starts,
        times=times,
        phase_index=index,
        elapsed=times - starts[index],
        features=np.zeros((n, 0)),
        end=float(times[-1]),
    )
    phases = ("insertion", "approach", "mating")  # the characteriser's order, not the trial's
    onset = max(float(times[onset_tick]) + offset, 0.0)
    ticks = [
        EvidenceTick(times[i], tf.phases[index[i]], tf.elapsed[i], z[i], means[i]) for i in range(n)
    ]
    alarm = max(onset_tick, alarm_tick)
    reference = np.searchsorted(times, onset - config.contact_reference_s + 1e-9, "right") - 1
    first = min(first_kept, max(int(reference), 0), alarm)  # kept from the reference on
    ev = RunningEvidence.begin(phases, onset, config, ticks[first : alarm + 1])
    if times[alarm] < onset - 1e-9:
        return  # no tick of the evidence yet: the live session names no class
    for i in range(alarm, n):
        if i > alarm:
            ev.add(ticks[i])
        until = float(times[i])
        assert np.array_equal(ev.features(), evidence_features(tf, z, phases, onset, until))
        want = contact_geometry(times, means, onset, until, config)
        got = ev.geometry(until)
        assert (got is None and want is None) or np.array_equal(got, want)


def test_a_contact_forest_of_fewer_classes_gives_the_others_nothing() -> None:
    rng = np.random.default_rng(3)
    X = rng.normal(size=(40, 2))
    head = ForestHead.fit(X, ["a" if x[0] > 0 else "c" for x in X], trees=5)
    p = head.predict_proba(X[:1])[0]
    assert head.proba_over(("a", "b", "c"), X[:1]) == pytest.approx([p[0], 0.0, p[1]])
    assert head.proba_over(("c", "a"), X[:1]) == pytest.approx([p[1], p[0]])


@pytest.mark.parametrize(
    "weights, field",
    [
        ("{z: 0.2}", "contact_weights.z"),
        ("{y: 1.5}", "contact_weights.y"),
        ("{y: .nan}", "contact_weights.y"),
    ],
)
def test_contact_weights_are_checked(tmp_path: Path, weights: str, field: str) -> None:
    path = tmp_path / "verify.yaml"
    path.write_text(f"verify:\n  contact_weights: {weights}\n")
    with pytest.raises(InputError, match=f"line 2, field verify.{field}: "):
        load_verify_config(path)


def test_channel_columns_read_only_the_named_wrench_axes() -> None:
    phases = ("approach", "insertion")
    names = feature_names(["right", "left"])
    evidence = [f"{b}:{n}" for b in ("mean", "max", "min") for n in names]
    evidence += [*(f"start:{p}" for p in phases), "start:elapsed"]
    cols = channel_columns(len(evidence), len(phases), ("Fx", "My"))
    picked = [evidence[c] for c in cols]
    assert picked[-3:] == ["start:approach", "start:insertion", "start:elapsed"]
    assert all(n.endswith((".Fx", ".My")) for n in picked[:-3])
    assert len(picked) - 3 == 3 * 2 * len(KINDS) * 2  # blocks x arms x kinds x axes


def test_narrow_direction_heads_ignore_the_other_axes_and_phase_in(
    trials: list[Trial], labels: dict[str, TrialLabel]
) -> None:
    """A narrow head reads only its wrench axes; at onset it has no say, from
    direction_ramp_s on it names the direction alone (no contact geometry here)."""
    config = load_verify_config()
    model = train_verifier(trials, labels, config)
    ch, envelope = model.characteriser, model.detector.models.envelope
    assert ch is not None and envelope is not None
    full = dataclasses.replace(ch, narrow={})
    ramp = config.direction_ramp_s
    tf = trial_features(trials[-1], config)
    x = evidence_features(tf, envelope.z(tf), ch.phases, float(tf.times[5]), tf.end)
    assert ch.predict_from(x, None, 0.0) == full.predict_from(x, None, 0.0)
    for axis in ("x", "r"):
        narrow, cols = ch.narrow[axis], ch.columns[axis]
        assert narrow.forest.n_features_in_ == len(cols) < len(x)
        moved = x.copy()
        moved[np.setdiff1d(np.arange(len(x)), cols)] += 7.0
        assert np.array_equal(
            narrow.predict_proba(moved[None, cols]), narrow.predict_proba(x[None, cols])
        )
        alone = narrow.classes[int(np.argmax(narrow.predict_proba(x[None, cols])[0]))]
        assert ch.predict_from(moved, None, ramp)[2][axis] == alone
        assert ch.predict_from(x, None, 2 * ramp)[2][axis] == alone
    plain = dataclasses.replace(config, direction_channels={})
    every = train_verifier(trials, labels, plain).characteriser
    assert every is not None and not every.narrow and not every.columns


def test_the_sign_table_ties_signs_to_a_class_only_when_unambiguous() -> None:
    def fail(cls: str, dev: tuple[float, float, float] | None) -> TrialLabel:
        return TrialLabel("t", "failure", cls, 1.0, dev)

    table = sign_table(
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
    assert table == {("+", "0", "0"): "slip_x"}


def test_direction_signs_weigh_in_on_which_deviation_is_named() -> None:
    """Real forests on two features: the class by the first, the signs by the second. Where
    the class head names one deviation and the direction heads are sure of another's signs,
    that one is named and takes the class head's probability for its pick; where they cannot
    tell, or the class head names no deviation, the class head's pick stands."""
    rng = np.random.default_rng(5)
    X = rng.uniform(-3, 3, size=(400, 2))
    klass = ["dev_a" if a > 1 else "dev_b" if a > 0 else "jam" for a in X[:, 0]]
    pos = X[:, 1] > 0
    noisy = pos ^ (np.abs(X[:, 1]) < 0.5) & (rng.random(len(X)) < 0.5)  # no sign near 0
    config = dataclasses.replace(load_verify_config(), contact_weights={}, direction_channels={})
    directions = {
        "x": ForestHead.fit(X, ["+" if p else "0" for p in noisy], 20),
        "y": ForestHead.fit(X, ["0" if p else "-" for p in noisy], 20),
        "r": ForestHead.fit(X, ["0" if p else "+" for p in noisy], 20),
    }
    signs = {("0", "-", "+"): "dev_a", ("+", "0", "0"): "dev_b"}
    ch = Characteriser((), ForestHead.fit(X, klass, 20), directions, config, signs=signs)
    alone = dataclasses.replace(ch, config=dataclasses.replace(config, direction_weight=0.0))
    late = config.direction_ramp_s
    for row, head_says, named in (
        ([2.5, 2.5], "dev_a", "dev_b"),  # sure of + 0 0: dev_b
        ([2.5, -2.5], "dev_a", "dev_a"),  # sure of 0 - +: dev_a, as the class head says
        ([2.5, 0.0], "dev_a", "dev_a"),  # unsure: the class head's pick
        ([-2.5, 2.5], "jam", "jam"),  # not a deviation: the signs do not rename it
    ):
        x = np.array(row)
        first, p_head, _ = alone.predict_from(x, None, late)
        assert ch.predict_from(x, None, 0.0)[0] == first  # at onset the signs have no say
        cls, probs, _ = ch.predict_from(x, None, late)
        assert first == head_says and cls == named, row
        assert probs[cls] == max(probs.values()) == p_head[head_says]
        assert probs[head_says] == p_head[cls]
        assert sum(probs.values()) == pytest.approx(1.0)


def test_the_config_names_the_characteriser_heads() -> None:
    assert (FAILURE, *DIRECTION_AXES) == CHARACTERISER_HEADS


def test_contact_forests_vote_only_where_the_part_touched(
    trials: list[Trial], labels: dict[str, TrialLabel]
) -> None:
    """Without contact weights there are no contact forests, and the envelope forests are the
    same; with them, evidence where nothing touched is named by the envelope forests alone;
    the timing view, which reads no wrench, gets none."""
    config = load_verify_config()
    trained = train_verifier(trials, labels, config)
    with_contact = trained.characteriser
    plain = dataclasses.replace(config, contact_weights={})
    without = train_verifier(trials, labels, plain).characteriser
    assert with_contact is not None and without is not None
    assert with_contact.contact and not without.contact
    envelope_only = dataclasses.replace(with_contact, contact={})
    model = trained.detector.models.envelope
    assert model is not None
    touched = 0
    for trial in trials:
        tf = trial_features(trial, config)
        z, means = model.z(tf), wrench_means(tf)
        onset = float(tf.times[len(tf.times) // 2])
        want = envelope_only.predict(tf, z, onset, tf.end, means)
        assert without.predict(tf, z, onset, tf.end, means) == want
        still = np.repeat(means[:1], len(means), axis=0)  # nothing touched
        assert with_contact.predict(tf, z, onset, tf.end, still) == envelope_only.predict(
            tf, z, onset, tf.end, still
        )
        touched += with_contact.predict(tf, z, onset, tf.end, means)[1] != want[1]
    assert touched  # and where the part touched, the contact forests do weigh in
    timing = trained.detector.models.timing
    assert timing is not None
    failed = [
        (trial_features(t, config), labels[t.name], labels[t.name].onset)
        for t in trials
        if labels[t.name].failed
    ]
    assert not Characteriser.fit(failed, timing, config).contact  # a view of no wrench


def test_an_injected_contact_anomaly_raises_the_alarm_after_it(
    trials: list[Trial], labels: dict[str, TrialLabel]
) -> None:
    config = load_verify_config()
    successes = [t for t in trials if not labels[t.name].failed]
    held = successes[-1]
    detector = Detector.fit([trial_features(t, config) for t in successes[:-1]], config)
    onset = float(held.state_times[1]) + 1.0  # in rotation: the part presses on the housing
    bumped = _jammed(held, onset)
    plain = detector.run(trial_features(held, config))
    hit = detector.run(trial_features(bumped, config))
    assert hit.alarm is not None and onset <= hit.alarm <= onset + GATE_S
    assert hit.onset is not None and hit.onset <= hit.alarm
    assert plain.alarm is None or plain.alarm > hit.alarm


def _jammed(trial: Trial, onset: float) -> Trial:
    """The trial with a jam from `onset`: 30 N more push, wedged about 17 mm off-centre."""
    wrench = trial.wrench["R"].copy()
    after = np.asarray(trial.time) >= onset
    wrench[after, 2] += 30.0
    wrench[after, 4] += 0.5
    return dataclasses.replace(trial, wrench={"R": wrench})


@pytest.fixture(scope="module")
def cell_successes() -> list[Trial]:
    """Ten successes of the repeated-program cell (config/sim_cell.yaml), whose nominal runs
    are alike, as a fixed robot program's are."""
    cell = load_sim_config(Path(__file__).resolve().parents[1] / "config" / "sim_cell.yaml")
    return [simulate_trial(cell, 500 + i, name=f"S-{i:02d}") for i in range(10)]


@pytest.mark.parametrize("fence", [3.0, 0.0])
def test_a_success_unlike_the_others_is_left_out_of_the_nominal_model(
    cell_successes: list[Trial], fence: float
) -> None:
    """A 'success' that jammed and still ended well (as a slip that snapped in) among the
    training successes: left out and named, the same jam on a held-out trial raises the alarm
    within the gate; kept (fence 0), it hides that jam."""
    config = dataclasses.replace(load_verify_config(), nominal_fence_iqr=fence)
    first, held = cell_successes[0], cell_successes[-1]
    odd = _jammed(first, float(first.state_times[1]) + 1.0)
    train = [odd, *cell_successes[1:-1]]
    model = train_verifier(train, {t.name: label_of(t) for t in train}, config)
    detector = model.detector
    assert model.trained_on["successes_left_out"] == list(detector.left_out)
    onset = float(held.state_times[1]) + 1.0
    hit = detector.run(trial_features(_jammed(held, onset), config))
    assert detector.run(trial_features(held, config)).alarm is None
    if fence:
        assert detector.left_out == (odd.name,)
        assert detector.calibration["successes"] == len(train) - 1
        assert hit.alarm is not None and onset <= hit.alarm <= onset + GATE_S
    else:
        assert detector.left_out == ()
        assert hit.alarm is None or hit.alarm > onset + GATE_S


def test_verifier_file_refuses_tampering(
    trials: list[Trial], labels: dict[str, TrialLabel], tmp_path: Path
) -> None:
    path = save_verifier(train_verifier(trials, labels, load_verify_config()), tmp_path / "v.npz")
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
    # a consistent file (checksum rewritten) whose contact weights do not fit its forests
    for weights, match in (
        ({"class": 0.2, "x": 0.2, "y": 2.0}, "field config.contact_weights.y"),
        ({"class": 0.2}, "'y', which has no contact weight"),
    ):
        edited = json.loads(json.dumps(header))
        edited["config"]["contact_weights"] = weights
        write_safe_npz(bad, edited, arrays)
        with pytest.raises(InputError, match=match):
            load_verifier(bad)
    # ... whose narrow direction head reads other columns than its config names, or whose sign
    # table names no class
    edited = json.loads(json.dumps(header))
    edited["config"]["direction_channels"]["x"] = ["Fx"]
    write_safe_npz(bad, edited, arrays)
    with pytest.raises(InputError, match="the narrow x head reads other columns"):
        load_verifier(bad)
    edited = json.loads(json.dumps(header))
    edited["characteriser"]["signs"] = [["0", "-", "+", "no_such_class"]]
    write_safe_npz(bad, edited, arrays)
    with pytest.raises(InputError, match="unknown class 'no_such_class'"):
        load_verifier(bad)


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


def test_labels_file(tmp_path: Path) -> None:
    path = tmp_path / "labels.csv"
    path.write_text(
        "trial,outcome,failure_class,onset_s,dev_x_mm,dev_y_mm,dev_yaw_deg\n"
        "a,failure,slip,12.5,2,,-3\n"
        "b,success,,,,,\n"
    )
    got = read_labels(path)
    assert got["a"].onset == 12.5 and got["a"].directions() == {"x": "+", "y": "0", "r": "-"}
    assert not got["b"].failed
    path.write_text(
        "trial,outcome,failure_class,onset_s,dev_x_mm,dev_y_mm,dev_yaw_deg\nc,failure,slip,soon,,,\n"
    )
    with pytest.raises(InputError) as err:
        read_labels(path)
    assert "line 2" in str(err.value) and "onset_s" in str(err.value)


def test_verify_eval_cli_reports_the_verifier_beside_both_baselines(
    trials: list[Trial], tmp_path: Path
) -> None:
    from rcbht_introspection.cli import main
    from rcbht_introspection.io.hiro import write_trial

    for t in trials:
        folder = write_trial(t, tmp_path / "set" / t.name)
        if "failure" in t.metadata:
            (folder / "meta.json").write_text(json.dumps(t.metadata))
    out = tmp_path / "v.json"
    assert main(["verify-eval", str(tmp_path / "set"), "--folds", "2", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    for m in (result, *result["baselines"].values()):
        assert 0 <= m["roc_auc"] <= 1 and 0 <= m["false_alarms_per_nominal_run"] <= 1
        assert m["failure_runs"] == len(FAILURES)
    assert set(result["baselines"]) == {"raw_wrench", "timing"}
    assert result["protocol"]["onset_source"] == {"label": len(FAILURES)}
    left = result["protocol"]["successes_left_out"]  # per method: trial -> folds (of 2)
    assert set(left) <= {"verifier", "raw_wrench", "timing"}
    assert all(1 <= folds <= 2 for trials in left.values() for folds in trials.values())
    assert "verifier_mismatch" not in result  # no classifier given
    # with a sub-task classifier (trained on other trials): the verifier with the mismatch
    # signal too, on the same runs; it can only add alarms to the verifier's
    model = tmp_path / "cls.rcbht"
    successes = tmp_path / "successes"
    for t in trials[:4]:
        write_trial(t, successes / t.name)
    assert main(["train", str(successes), "--out", str(model)]) == 0
    args = ["verify-eval", str(tmp_path / "set"), "--folds", "2", "--model", str(model)]
    assert main([*args, "--json", str(out)]) == 0
    with_model = json.loads(out.read_text())
    both = with_model["verifier_mismatch"]
    verifier_runs = [r for r in with_model["runs"] if r["method"] == "verifier"]
    assert both["runs"] == len(verifier_runs) == len(trials) and 0 <= both["roc_auc"] <= 1
    alarms = {m: {r["trial"]: r["alarm"] for r in with_model["runs"] if r["method"] == m} for m in ("verifier", "verifier_mismatch")}  # fmt: skip
    for name, alarm in alarms["verifier"].items():
        if alarm is not None:
            assert alarms["verifier_mismatch"][name] is not None
            assert alarms["verifier_mismatch"][name] <= alarm


def test_live_session_with_a_late_first_event_equals_the_batch_detector(
    trials: list[Trial], labels: dict[str, TrialLabel]
) -> None:
    """A robot streams wrench before its state machine's first event: the ticks before it are
    judged 'no sub-task yet', and an alarm's evidence still stacks."""
    config = load_verify_config()
    model = train_verifier(trials, labels, config)
    failing = trials[-1]
    late = dataclasses.replace(failing, state_times=(0.5, *failing.state_times[1:]))
    tf = trial_features(late, config)
    batch = model.detector.run(tf)
    verdicts = offline_verdicts(late, model)
    np.testing.assert_allclose([v.score for v in verdicts], batch.score, rtol=1e-12)
    assert verdicts[-1].alarm_time == batch.alarm
    assert verdicts[0].phase == "" and verdicts[-1].phase != ""


def test_two_arms_with_offset_stamps_and_a_silent_arm_still_give_verdicts(
    trials: list[Trial], labels: dict[str, TrialLabel]
) -> None:
    both = [dataclasses.replace(t, wrench={"L": t.wrench["R"], "R": t.wrench["R"]}) for t in trials]
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


def test_labels_file_refuses_bad_text_and_accepts_a_byte_order_mark(tmp_path: Path) -> None:
    header = "trial,outcome,failure_class,onset_s,dev_x_mm,dev_y_mm,dev_yaw_deg\n"
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
    labels.write_text(
        "trial,outcome,failure_class,onset_s,dev_x_mm,dev_y_mm,dev_yaw_deg\n"
        f"{trials[0].name}x,failure,slip,,,,\n"
    )
    args = ["verify-train", str(tmp_path / "set"), "--labels", str(labels), "--out", "v.npz"]
    assert main([*args, "--strict"]) == 2


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


def test_live_session_with_a_contradiction_equals_the_batch_mismatch_rule(
    trials: list[Trial], labels: dict[str, TrialLabel]
) -> None:
    """A contradicting final verdict raises the alarm at the first tick it is known, with the
    contradicted sub-task's start as onset; the live session and the batch rule agree."""
    from rcbht_introspection.verify.mismatch import MISMATCH, Contradiction, with_mismatch

    config = load_verify_config()
    model = train_verifier(trials[1:], labels, config)
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

"""Teaching the live classifier without DDS (learn/teaching.py): a cold-started session is taught
generated trials' sub-tasks, swaps the taught model in, saves it, and refuses bad requests."""

from __future__ import annotations

import os
import signal
from dataclasses import replace
from pathlib import Path

import pytest
from conftest import generated_trials

from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar.split import SubtaskSample
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.learn.learner_process import ProcessLearner
from rcbht_introspection.learn.live import sample_word_count
from rcbht_introspection.learn.model_file import load_model
from rcbht_introspection.learn.online import LEARNERS, TeachConfig
from rcbht_introspection.learn.teaching import Teaching, _Job
from rcbht_introspection.live.belief import UNKNOWN, Belief, BeliefTracker
from rcbht_introspection.live.classifier import ClassifierSession, PhaseInput, WordsInput
from rcbht_introspection.live.state import StateFilter
from rcbht_introspection.live.teach import TeachRequest
from rcbht_introspection.taxonomy.words import LEVELS, Word
from rcbht_introspection.waiting import wait_until

CONFIG = TeachConfig(n_estimators=10, learner="thread")
"""A small forest learned in the worker thread: the tests check the queue, not the accuracy
(the learner's own process is tested on its own and in the first test)."""


def _words(trial: Trial) -> list[Word]:
    from rcbht_introspection.taxonomy.batch import label_trial

    tw = label_trial(trial)
    # unnumbered (seq 0): the batch engine's numbers are not one stream's release order
    out = [
        replace(w, seq=0)
        for lv in tw.words.values()
        for ax in lv.values()
        for seq in ax.values()
        for w in seq
    ]
    return sorted(out, key=lambda w: (w.end, LEVELS.index(w.level)))


def _feed(
    session: ClassifierSession,
    trial: Trial,
    stream: int,
    after_subtask: list[TeachRequest] | None = None,
) -> list[Belief]:
    """Play `trial` into the session as the node would (stream `stream`); the final verdicts.

    `after_subtask`: send a `last` request with the true label right after each boundary."""
    key = (1_000_000_000 * (stream + 1), stream)
    events = [(t, s) for s, t, _ in trial.subtask_bounds()] + [(trial.end_time, "done")]
    truth = [s for s, _, _ in trial.subtask_bounds()]
    finals: list[Belief] = []
    i = 0

    def receive(items: list[WordsInput | PhaseInput]) -> None:
        finals.extend(b for b, _ in session.receive(items).beliefs if b.final)

    for w in _words(trial):
        while i < len(events) and events[i][0] <= w.start:
            t, name = events[i]
            receive([PhaseInput(name, t, key[0] + round(t * 1e9), key)])
            if after_subtask is not None and i > 0:
                req = TeachRequest(truth[i - 1], last=True, request_id=f"{stream}-{i}")
                after_subtask.append(req)
                assert session.teach(req).accepted
            i += 1
        stamp = key[0] + round(w.end * 1e9)
        receive([WordsInput("R", w.level, [w], w.end, stamp, key, 1, False, 0)])
    for t, name in events[i:]:
        receive([PhaseInput(name, t, key[0] + round(t * 1e9), key)])
    if after_subtask is not None:
        req = TeachRequest(truth[-1], last=True, request_id=f"{stream}-end")
        after_subtask.append(req)
        assert session.teach(req).accepted
    end = key[0] + round(trial.end_time * 1e9)
    receive([WordsInput("R", lv, [], trial.end_time, end, key, 1, True, 0) for lv in LEVELS])
    return finals


def _session(teaching: Teaching | None, model: object = None) -> ClassifierSession:
    tracker = BeliefTracker(model, history_s=60.0)  # type: ignore[arg-type]
    return ClassifierSession(tracker, StateFilter(), teaching=teaching)


@pytest.fixture(scope="module")
def trials(request: pytest.FixtureRequest) -> list[Trial]:
    from rcbht_introspection.io.hiro import read_trial

    return [read_trial(p) for p in generated_trials(request)[:3]]


@pytest.mark.parametrize("learner", LEARNERS)
def test_cold_start_learns_taught_windows_swaps_and_saves(
    trials: list[Trial], tmp_path: Path, learner: str
) -> None:
    saved = tmp_path / "taught.rcbht"
    teaching = Teaching(replace(CONFIG, learner=learner), None, saved)
    session = _session(teaching)
    first, second, held_out = trials
    # no model: every verdict is unknown while nothing is taught
    assert {b.subtask for b in _feed(session, first, 0)} == {UNKNOWN}
    # the finished trial's sub-tasks by their true [start, end], as the replay harness does
    bounds = first.subtask_bounds()
    for name, start, end in bounds:
        status = session.teach(TeachRequest(name, last=False, start=start, end=end))
        assert status.accepted, status.message
    # the second trial labelled live: each sub-task right after it ended (its words not yet final)
    sent: list[TeachRequest] = []
    _feed(session, second, 1, after_subtask=sent)
    assert [r.label for r in sent] == [s for s, _, _ in second.subtask_bounds()]
    assert wait_until(lambda: teaching.status().pending == 0, timeout=120)
    status = teaching.status()
    assert status.taught_windows == len(bounds) + len(sent)
    assert status.model_version >= 1 and status.errors == 0
    # the taught model is saved atomically (checksum verified on load), nothing else left behind
    model = load_model(saved)
    assert sorted(model.classes_) == sorted({s for s, _, _ in bounds})
    assert [p.name for p in tmp_path.iterdir()] == [saved.name]
    # the live path takes it at its next classification: verdicts on a held-out trial are
    # those of the saved model in a fresh session
    live = _feed(session, held_out, 2)
    assert session.tracker.model is not None
    assert all(b.subtask != UNKNOWN for b in live)
    restarted = _feed(_session(None, model), held_out, 0)
    assert [b.subtask for b in live] == [b.subtask for b in restarted]
    assert [b.probabilities for b in live] == [b.probabilities for b in restarted]
    teaching.close()


def test_bad_requests_are_refused_counted_and_never_raise(trials: list[Trial]) -> None:
    teaching = Teaching(CONFIG)
    session = _session(teaching)
    refused = []
    # nothing has ended yet: `last` names no window
    refused.append(session.teach(TeachRequest("approach", last=True)))
    _feed(session, trials[0], 0)
    tracker = session.tracker
    for req in (
        TeachRequest("approach", last=False, start=5.0, end=1.0),  # not an interval
        TeachRequest("approach", last=False, start=float("nan"), end=1.0),
        TeachRequest("approach", last=False, start=0.0, end=tracker.now + 10),  # not seen yet
        TeachRequest(UNKNOWN),
        TeachRequest("done"),  # an end phase
        TeachRequest(" approach"),
    ):
        refused.append(session.teach(req))
    # words dropped: a window before what the tracker keeps
    tracker.kept_from = 1.0
    refused.append(session.teach(TeachRequest("approach", last=False, start=0.0, end=2.0)))
    # a window without words: after the last word, before the stream's end time
    tracker.words.words.clear()
    refused.append(session.teach(TeachRequest("approach", last=False, start=2.0, end=3.0)))
    assert [s.accepted for s in refused] == [False] * len(refused)
    assert all(s.message and "\n" not in s.message for s in refused)
    assert teaching.counts["teach requests refused"] == len(refused)
    assert teaching.status().errors == len(refused) and teaching.status().pending == 0
    # the empty label only asks for the status
    status = session.teach(TeachRequest(""))
    assert status.accepted and status.taught_windows == 0 and status.errors == len(refused)
    teaching.close()


def test_a_svm_model_cannot_be_taught(trials: list[Trial]) -> None:
    from rcbht_introspection.grammar.split import split_words
    from rcbht_introspection.learn.models import train_model
    from rcbht_introspection.live.offline import trial_words

    trial = trials[0]
    words = trial_words(trial.name, {"R": _words(trial)})
    svm = train_model(split_words(words, trial.state_times, trial.end_time))
    teaching = Teaching(CONFIG, svm)
    session = _session(teaching, svm)
    _feed(session, trial, 0)
    status = session.teach(TeachRequest("approach"))
    assert not status.accepted and "Mondrian" in status.message
    assert teaching.counts["teach requests refused"] == 1
    teaching.close()


def test_unavailable_teaching_starts_no_learner(trials: list[Trial]) -> None:
    """The node's reason (a model file it must not overwrite) refuses every request, and no
    learner process is started for it."""
    reason = "model file m.rcbht exists but is not usable (corrupt); teaching would overwrite it"
    teaching = Teaching(replace(CONFIG, learner="process"), unavailable=reason)
    assert teaching.learner is None and teaching.process is None
    assert teaching.where_learned() == "none (teaching unavailable)"
    session = _session(teaching)
    _feed(session, trials[0], 0)
    status = session.teach(TeachRequest("approach"))
    assert not status.accepted and status.message == reason
    teaching.close()


def test_a_resent_request_is_taught_once(trials: list[Trial]) -> None:
    teaching = Teaching(CONFIG)
    session = _session(teaching)
    _feed(session, trials[0], 0)
    req = TeachRequest("mating", last=True, request_id="abc")
    assert session.teach(req).accepted
    assert session.teach(req).accepted  # the client did not hear the first answer
    assert wait_until(lambda: teaching.status().pending == 0, timeout=60)
    assert teaching.status().taught_windows == 1
    bad = TeachRequest("mating", last=False, start=3.0, end=1.0, request_id="def")
    assert not session.teach(bad).accepted
    assert not session.teach(bad).accepted  # refused again, counted once
    assert teaching.counts["teach requests refused"] == 1
    teaching.close()


def test_teaching_off_refuses(trials: list[Trial]) -> None:
    session = _session(None)
    status = session.teach(TeachRequest("approach"))
    assert not status.accepted and "teaching is off" in status.message


def test_tracker_keeps_the_last_subtask_and_recent_words_for_teaching(
    trials: list[Trial],
) -> None:
    trial = trials[0]
    kept = _session(None)
    _feed(kept, trial, 0)
    name, start, end = kept.tracker.last_subtask()  # type: ignore[misc]
    assert (name, start, end) == trial.subtask_bounds()[-1]

    def words_in(tracker: BeliefTracker, lo: float, hi: float) -> int:
        """Words that end in [lo, hi]."""
        return sum(
            1
            for lv in tracker.words.words.values()
            for ax in lv.values()
            for seq in ax.values()
            for w in seq
            if w.end >= lo and w.start <= hi
        )

    # with teaching (history 60 s): the whole short trial is still there
    _, first_start, first_end = trial.subtask_bounds()[0]
    first = words_in(kept.tracker, first_start, first_end)
    assert first > 0
    # without: words of finished sub-tasks go once their verdict is issued
    plain = ClassifierSession(BeliefTracker(None), StateFilter())
    _feed(plain, trial, 0)
    assert words_in(plain.tracker, first_start, first_end) < first / 10
    # bounded: a short history keeps the last sub-task, not the ones before it
    short = ClassifierSession(BeliefTracker(None, history_s=0.1), StateFilter())
    _feed(short, trial, 0)
    assert words_in(short.tracker, start, end) > 0
    assert words_in(short.tracker, first_start, first_end) < first / 10


def test_the_last_subtask_is_refused_once_its_words_are_pruned(trials: list[Trial]) -> None:
    """teach_history_s 0: the words of a finished sub-task go with its verdict, so `last` no
    longer names a whole window and is refused (not taught from what is left)."""
    teaching = Teaching(CONFIG)
    session = ClassifierSession(
        BeliefTracker(None, history_s=0.0), StateFilter(), teaching=teaching
    )
    _feed(session, trials[0], 0)
    status = session.teach(TeachRequest("mating", last=True))
    assert not status.accepted and "no longer kept" in status.message
    assert teaching.counts["teach requests refused"] == 1
    teaching.close()


def test_live_like_windows_hold_only_words_final_by_their_time(trials: list[Trial]) -> None:
    """With live_windows, a taught window also teaches what its running window held at times
    inside it: the words final by then (as learn/live.py's live_windows), never a later one."""
    from rcbht_introspection.learn.live import LiveAugmentConfig

    teaching = Teaching(CONFIG, live_windows=LiveAugmentConfig())
    session = _session(teaching)
    trial = trials[0]
    _feed(session, trial, 0)
    name, start, end = max(trial.subtask_bounds(), key=lambda b: b[2] - b[1])
    job_live = teaching._live_samples(  # what the request below queues
        _Job(TeachRequest(name, False, start, end), start, end), session.tracker
    )
    assert len(job_live) >= 3
    for sample in job_live:
        assert sample.subtask == name and sample.start == start
        arrived = session.tracker.words_final_by(sample.end, start)
        for level in sample.words.words.get("R", {}).values():
            for axis, words in level.items():
                assert all(w.end <= sample.end + 1e-9 for w in words), axis
        assert sample_word_count(sample) <= sum(
            len(ws) for lv in arrived.words.values() for ax in lv.values() for ws in ax.values()
        )
    status = session.teach(TeachRequest(name, last=False, start=start, end=end))
    assert status.accepted, status.message
    assert wait_until(lambda: teaching.status().pending == 0, timeout=120)
    assert teaching.learner is not None and teaching.learner.taught_live == len(job_live)
    teaching.close()


def _samples(trial: Trial) -> list[SubtaskSample]:
    from rcbht_introspection.grammar.split import split_words
    from rcbht_introspection.live.offline import trial_words

    words = trial_words(trial.name, {"R": _words(trial)})
    return split_words(words, trial.state_times, trial.end_time)


def test_the_learner_process_answers_failures_and_ends(trials: list[Trial], tmp_path: Path) -> None:
    """The learner's own process: a teach file it cannot write still gives the model (and says
    why); a refused teach raises InputError and changes nothing; a killed process is a
    RuntimeError with its exit code, not a hang; close() ends it."""
    config = TeachConfig(n_estimators=10)
    samples = _samples(trials[0])
    (tmp_path / "a_file").write_text("not a folder")
    learner = ProcessLearner(config, out_path=tmp_path / "a_file" / "taught.rcbht")
    try:
        model, save_error = learner.teach(samples)
        assert save_error and "\n" not in save_error
        assert sorted(model.classes_) == sorted({s.subtask for s in samples})
        with pytest.raises(InputError, match="nothing to teach"):
            learner.teach([])
        again, _ = learner.teach(_samples(trials[1]))  # the refusal changed nothing
        assert sorted(again.classes_) == sorted(model.classes_)
    finally:
        learner.close()
    assert not learner.alive
    killed = ProcessLearner(config)
    try:
        killed.teach(samples)
        os.kill(killed.pid, signal.SIGKILL)
        with pytest.raises(RuntimeError, match="exit code -9"):
            killed.teach(samples)
    finally:
        killed.close()

"""Teaching the live classifier (pure core): labelled windows in, taught models out, never blocking.

A request names a label (a sub-task name or a failure class) and a window: the sub-task that
ended last, or [start, end] in stream seconds. Its words are taken from the belief tracker when
the request arrives (on the live path's thread; a window whose words are not all final yet
waits for them at the next classifications), queued, and learned by an OnlineLearner
(online.py) for one worker thread: in a process of its own (learner_process.py, the default:
learning then never holds the live path's GIL) or in the worker thread itself
(TeachConfig.learner). Each new model is saved atomically (when a path is
given) and put into a one-model slot that the live path takes at its next classification: the
live path never waits for learning and never sees a half-updated model. A bad request is
refused with a one-line reason and counted, never raised.
"""

from __future__ import annotations

import math
import queue
import threading
import time
from collections import OrderedDict, deque
from dataclasses import dataclass, replace
from pathlib import Path

from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar.split import SubtaskSample, window_sample
from rcbht_introspection.learn.learner_process import ProcessLearner
from rcbht_introspection.learn.live import LiveAugmentConfig, sample_times, sample_word_count
from rcbht_introspection.learn.model_file import save_model
from rcbht_introspection.learn.models import SubtaskModel
from rcbht_introspection.learn.online import OnlineLearner, TeachConfig
from rcbht_introspection.live.belief import UNKNOWN, BeliefTracker
from rcbht_introspection.live.health import file_sha256
from rcbht_introspection.live.teach import TeachRequest, TeachStatus

TEACH_COUNTS = ("teach requests refused", "teach updates failed")
"""What teaching counts (the classifier's /diagnostics values, beside live/classifier.COUNTS)."""
REMEMBERED_IDS = 1000
"""Request ids remembered, so a re-sent request is answered again but not taught twice."""


@dataclass
class _Job:
    """An accepted request and its window; `sample` once the window's words are final."""

    request: TeachRequest
    start: float
    end: float
    sample: SubtaskSample | None = None
    live: tuple[SubtaskSample, ...] = ()
    """Live-like windows [start, t] of the words final by t, labelled as the window."""
    accepted_at: float = 0.0


class ModelSlot:
    """The one place a taught model passes from the worker to the live path (latest wins)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._model: SubtaskModel | None = None

    def put(self, model: SubtaskModel) -> None:
        with self._lock:
            self._model = model

    def take(self) -> SubtaskModel | None:
        """The model put since the last take, else None."""
        with self._lock:
            model, self._model = self._model, None
        return model


class Teaching:
    """The teach queue and its worker around an OnlineLearner (see the module doc).

    `request`, `collect` and `take_model` run on the live path's thread (they touch the
    tracker); the worker only learns, saves and fills the slot.
    """

    def __init__(
        self,
        config: TeachConfig,
        model: SubtaskModel | None = None,
        save_path: str | Path = "",
        counts: dict[str, int] | None = None,
        random_state: int = 0,
        taxonomy_profile: str = "reference",
        live_windows: LiveAugmentConfig | None = None,
        unavailable: str = "",
    ) -> None:
        self.save_path = Path(save_path) if save_path else None
        self.live_windows = live_windows
        """When live-like windows of a taught window are taken (config/live.yaml; None: none)."""
        self.counts = counts if counts is not None else {}
        for name in TEACH_COUNTS:
            self.counts.setdefault(name, 0)
        self.saved_sha256 = ""
        """SHA-256 of the last saved model file (for /diagnostics), '' before the first save."""
        self.unavailable = unavailable
        """Why nothing can be taught (the caller's reason, or a model that is not a Mondrian
        forest), else ''. Then no learner (and no learner process) is made."""
        self.learner: OnlineLearner | None = None
        if not self.unavailable and model is not None and model.classifier != "mondrian":
            self.unavailable = f"teaching needs a Mondrian forest model, not {model.classifier!r}"
        if not self.unavailable:
            try:
                self.learner = OnlineLearner(
                    config,
                    model,
                    model.task if model else None,
                    random_state,
                    taxonomy_profile=taxonomy_profile,
                )
            except InputError as exc:
                self.unavailable = str(exc)
        self.process: ProcessLearner | None = None
        """The learner's own process (TeachConfig.learner 'process'); the worker waits on it."""
        if self.learner is not None and config.learner == "process":
            self.process = ProcessLearner(config, model, save_path, random_state, taxonomy_profile)
        self.slot = ModelSlot()
        self.waiting: list[_Job] = []
        """Accepted jobs whose words are not all final yet (live thread only)."""
        self._queue: queue.Queue[_Job | None] = queue.Queue()
        self._lock = threading.Lock()
        self._pending = 0
        self.taught_windows = 0
        self.model_version = 0
        self.latencies_s: deque[float] = deque(maxlen=1000)
        """Request accepted -> model in the slot, per job (seconds; for benchmarks)."""
        self._notes: deque[tuple[str, str]] = deque(maxlen=100)
        self._answers: OrderedDict[str, TeachStatus] = OrderedDict()
        self._worker = threading.Thread(target=self._work, name="rcbht-teach", daemon=True)
        self._worker.start()

    # --- the live path's side ----------------------------------------------------------------
    def request(self, req: TeachRequest, tracker: BeliefTracker) -> TeachStatus:
        """Take a request: its window's words now (or once final), or a one-line refusal."""
        if req.request_id and req.request_id in self._answers:
            first = self._answers[req.request_id]  # a re-sent request: the same answer, now
            return replace(self.status(first.message), accepted=first.accepted)
        if not req.label:
            return self.status("status")
        problem = self._refusal(req, tracker)
        if problem:
            self.counts["teach requests refused"] += 1
            self._notes.append(("warning", f"teach request refused: {problem}"))
            return self._remember(req, replace(self.status(problem), accepted=False))
        start, end = self._window(req, tracker)
        job = _Job(req, start, end, accepted_at=time.perf_counter())
        with self._lock:
            self._pending += 1
        if tracker.complete(end):
            message = self._take_words(job, tracker)
            if message:
                return self._remember(req, replace(self.status(message), accepted=False))
        else:
            self.waiting.append(job)
            tracker.pinned_from = min(tracker.pinned_from, start)
        answer = self.status(
            f"{req.label!r} on [{start:.3f}, {end:.3f}] s "
            + ("queued" if job.sample is not None else "waits for its words to be final")
        )
        return self._remember(req, answer)

    def _remember(self, req: TeachRequest, answer: TeachStatus) -> TeachStatus:
        """Keep the answer to a request with an id (a repeat gets it again); returns it."""
        if req.request_id:
            self._answers[req.request_id] = answer
            while len(self._answers) > REMEMBERED_IDS:
                self._answers.popitem(last=False)
        return answer

    def collect(self, tracker: BeliefTracker, stream_ends: bool = False) -> None:
        """Queue the waiting windows whose words are final now (`stream_ends`: all of them,
        with the words they have, before the tracker forgets the stream)."""
        still = []
        for job in self.waiting:
            if stream_ends or tracker.complete(job.end):
                self._take_words(job, tracker)
            else:
                still.append(job)
        self.waiting = still
        tracker.pinned_from = min((j.start for j in still), default=math.inf)

    def take_model(self) -> SubtaskModel | None:
        """A taught model not yet handed over, else None (never waits for the worker)."""
        return self.slot.take()

    def status(self, message: str = "") -> TeachStatus:
        """Where teaching stands, with `message`."""
        with self._lock:
            pending, taught, version = self._pending, self.taught_windows, self.model_version
        errors = self.counts["teach requests refused"] + self.counts["teach updates failed"]
        return TeachStatus(True, message, pending, taught, version, errors)

    def where_learned(self) -> str:
        """'process PID' (the learner's own process; '(ended)' when it died), 'thread', or
        'none (teaching unavailable)'."""
        if self.learner is None:
            return "none (teaching unavailable)"
        if self.process is None:
            return "thread"
        return f"process {self.process.pid}" + ("" if self.process.alive else " (ended)")

    def notes(self) -> list[tuple[str, str]]:
        """(level, line) of what happened since the last call: for the node's log."""
        out = []
        while self._notes:
            out.append(self._notes.popleft())
        return out

    def _save(self, model: SubtaskModel) -> str:
        """Write `model` to the teach file (when one is given); why not, or ''."""
        if self.save_path is None:
            return ""
        try:
            save_model(model, self.save_path, compress=False)  # rewritten at every teach
        except OSError as exc:
            return str(exc)
        return ""

    def close(self, timeout: float = 10.0) -> None:
        """Stop the worker once the queued jobs are learned, then the learner's process; jobs
        still waiting for their words are dropped, counted (`teach requests dropped at
        shutdown`) and noted."""
        if self.waiting:
            dropped = len(self.waiting)
            self.counts["teach requests dropped at shutdown"] = (
                self.counts.get("teach requests dropped at shutdown", 0) + dropped
            )
            with self._lock:
                self._pending -= dropped
            self._notes.append(
                ("warning", f"{dropped} teach request(s) still waiting for their words dropped")
            )
            self.waiting = []
        self._queue.put(None)
        self._worker.join(timeout)
        if self.process is not None:  # kills a teach still running after `timeout`
            self.process.close(timeout)
            self._worker.join(timeout)
        if self._worker.is_alive():
            self._notes.append(("warning", f"the teach worker did not stop within {timeout} s"))

    def _refusal(self, req: TeachRequest, tracker: BeliefTracker) -> str:
        """Why `req` cannot be taught, or ''."""
        if self.unavailable:
            return self.unavailable
        label = req.label
        if label != label.strip() or label == UNKNOWN or label in tracker.end_phases:
            return f"not a usable label: {label!r}"
        if req.last:
            last = tracker.last_subtask()
            if last is None:
                return "unknown window: no sub-task has ended in this stream"
            if last[1] < tracker.kept_from:
                return (
                    f"unknown window: the last sub-task starts at {last[1]:.3f} s, the words "
                    f"before {tracker.kept_from:.3f} s are no longer kept (teach_history_s)"
                )
            return ""
        if not (math.isfinite(req.start) and math.isfinite(req.end)) or req.start > req.end:
            return f"unknown window: [{req.start}, {req.end}] is not a time interval"
        if req.start < tracker.kept_from:
            return (
                f"unknown window: it starts at {req.start:.3f} s, the words before "
                f"{tracker.kept_from:.3f} s are no longer kept (teach_history_s)"
            )
        if req.end > tracker.now:
            return (
                f"unknown window: it ends at {req.end:.3f} s, the stream is at {tracker.now:.3f} s"
            )
        return ""

    @staticmethod
    def _window(req: TeachRequest, tracker: BeliefTracker) -> tuple[float, float]:
        last = tracker.last_subtask()
        if req.last and last is not None:
            return last[1], last[2]
        return req.start, req.end

    def _take_words(self, job: _Job, tracker: BeliefTracker) -> str:
        """Cut the job's sample from the tracker's words and queue it; a refusal line or ''."""
        wrench = {arm: track.until(job.end) for arm, track in tracker.wrench.items()}
        sample = window_sample(
            tracker.words, job.start, job.end, job.request.label, tracker.trial, wrench=wrench
        )
        if not sample_word_count(sample):
            with self._lock:
                self._pending -= 1
            self.counts["teach requests refused"] += 1
            message = f"empty window: no words in [{job.start:.3f}, {job.end:.3f}] s"
            self._notes.append(("warning", f"teach request refused: {message}"))
            return message
        job.sample = sample
        job.live = self._live_samples(job, tracker)
        self._queue.put(job)
        return ""

    def _live_samples(self, job: _Job, tracker: BeliefTracker) -> tuple[SubtaskSample, ...]:
        """What the running window of the job's sub-task held at times inside it (the words
        final by then, as learn/live.py's live_windows): the classifier's running beliefs
        learn from these, not only from complete windows and their prefixes."""
        if self.live_windows is None:
            return ()
        out = []
        for t in sample_times(job.start, job.end, self.live_windows):
            words = tracker.words_final_by(t, job.start)
            wrench = {arm: track.until(t) for arm, track in tracker.wrench.items()}
            sample = window_sample(
                words, job.start, t, job.request.label, tracker.trial, wrench=wrench
            )
            if sample_word_count(sample):
                out.append(sample)
        return tuple(out)

    # --- the worker --------------------------------------------------------------------------
    def _work(self) -> None:
        """Learn every queued job as one batch, save, fill the slot; repeat until closed."""
        while True:
            first = self._queue.get()
            if first is None:
                return
            jobs = [first]
            while True:  # what else is queued goes into the same update
                try:
                    job = self._queue.get_nowait()
                except queue.Empty:
                    break
                if job is None:
                    self._queue.put(None)
                    break
                jobs.append(job)
            self._learn(jobs)

    def _learn(self, jobs: list[_Job]) -> None:
        assert self.learner is not None
        samples = [j.sample for j in jobs if j.sample is not None]
        live = [s for j in jobs for s in j.live]
        t0 = time.perf_counter()
        try:
            if self.process is not None:  # it writes the teach file itself
                model, save_error = self.process.teach(samples, live)
            else:
                model = self.learner.teach(samples, live)
                save_error = self._save(model)
        except Exception as exc:  # a failed update must not stop the worker or the node
            self.counts["teach updates failed"] += 1
            self._notes.append(("error", f"teach update failed: {type(exc).__name__}: {exc}"))
            with self._lock:
                self._pending -= len(jobs)
            return
        saved = ""
        if self.save_path is not None and not save_error:
            self.saved_sha256 = file_sha256(str(self.save_path))
            saved = f", saved to {self.save_path}"
        elif save_error:  # the live path still gets the model; the file is as it was
            self.counts["teach updates failed"] += 1
            self._notes.append(("error", f"taught model not saved: {self.save_path}: {save_error}"))
        self.slot.put(model)
        done = time.perf_counter()
        with self._lock:
            self.taught_windows += len(samples)
            self.model_version += 1
            self._pending -= len(jobs)
            version = self.model_version
        self.latencies_s.extend(done - j.accepted_at for j in jobs)
        labels = sorted({s.subtask for s in samples})
        self._notes.append(
            (
                "info",
                f"taught {len(samples)} window(s) {labels} in {done - t0:.2f} s: model version "
                f"{version}, classes {model.classes_}{saved}",
            )
        )

"""Sub-task belief from live words: the classifier node's state, pure Python.

Two modes. "boundary" (the paper's setting): the window is the words since the last sub-task
event; when the next event closes a sub-task, its final verdict is issued once every word
overlapping it is final (each arm's words reach its end on every level and axis, or the arm's
stream ended). "window": the words of the last `window_s` seconds, no state machine needed.
Times are stream seconds; a new stream (new time origin) starts a new session.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from typing import Any, Protocol

import numpy as np

from rcbht_introspection.grammar.encoding.axes import AxisMemo
from rcbht_introspection.grammar.split import SubtaskSample, window_sample
from rcbht_introspection.live import MODES, BeliefMode
from rcbht_introspection.live.join import WordLedger
from rcbht_introspection.summaries.blocks import WrenchBlock, WrenchTrack
from rcbht_introspection.taxonomy.words import AXES, LEVELS, Level, TrialWords, Word

UNKNOWN = "unknown"


@dataclass(frozen=True)
class Belief:
    """The believed sub-task of one window and the per-class probabilities behind it."""

    subtask: str
    classes: tuple[str, ...]
    probabilities: tuple[float, ...]
    start: float
    end: float
    mode: BeliefMode
    phase: str = ""
    final: bool = False
    n_words: int = 0
    blind: bool = False
    """The window overlaps words that never arrived: judged UNKNOWN whatever the model says."""


@dataclass
class _Segment:
    """A sub-task announced by the state machine: [start, end], end None while it runs."""

    phase: str
    start: float
    end: float | None = None


class SampleClassifier(Protocol):
    """What the tracker asks of a model: a SubtaskModel (learn/models.py) or a stand-in with
    these members. A model may also offer `head(final)` and take an AxisMemo (`takes_axis_memo`)."""

    @property
    def classes_(self) -> Sequence[Any]: ...

    def predict_proba_samples(self, samples: list[SubtaskSample]) -> Any: ...

    def predict_samples(self, samples: list[SubtaskSample]) -> Any: ...


class BeliefTracker:
    """Collects words, tracks sub-task events and classifies windows with a SubtaskModel."""

    def __init__(
        self,
        model: SampleClassifier | None,
        mode: BeliefMode = "boundary",
        window_s: float = 2.0,
        subtasks: Sequence[str] | None = None,
        end_phases: Sequence[str] = ("done",),
        trial: str = "live",
        history_s: float = 0.0,
    ) -> None:
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        self.model = model
        self.mode = mode
        self.window_s = float(window_s)
        task = getattr(model, "task", None)  # a SubtaskModel's; a stand-in: its classes
        if subtasks is None:
            subtasks = task.subtasks if task is not None else getattr(model, "classes_", ())
        self.subtasks = tuple(subtasks)
        """Names that start a sub-task (the model's task); empty: every name but an end phase."""
        ends = [*end_phases, *(task.end_phases if task is not None else ())]
        self.end_phases = tuple(dict.fromkeys(ends))
        """The given end phases and the model's task's."""
        self.trial = trial
        self.history_s = float(history_s)
        """> 0 (teaching): also keep the words of the last history_s stream seconds and of the
        last finished sub-task, so a label given after the fact finds its window's words."""
        self.classes: tuple[str, ...] = (
            tuple(str(c) for c in model.classes_) if model is not None else ()
        )
        self.last_error: str | None = None
        self.reset()

    def set_model(self, model: SampleClassifier) -> None:
        """Classify with `model` from now on (a taught model); the words and events stay.

        Sub-task event names: an open vocabulary (none given) stays open, a closed one grows by
        the new model's task."""
        self.model = model
        self.classes = tuple(str(c) for c in model.classes_)
        task = getattr(model, "task", None)
        if self.subtasks and task is not None:
            self.subtasks = tuple(dict.fromkeys((*self.subtasks, *task.subtasks)))
        if task is not None:
            self.end_phases = tuple(dict.fromkeys((*self.end_phases, *task.end_phases)))
        self._axis_memo = AxisMemo()  # features of the old encoding
        self.last_error = None

    def reset(self) -> None:
        """Start a new stream: no words, no sub-task events."""
        self.words = TrialWords(name=self.trial)
        self.wrench: dict[str, WrenchTrack] = {}
        """Per arm, the wrench block means of the stream (summaries/blocks.py)."""
        self.arrivals: dict[tuple[str, Level, str], list[float]] = {}
        """Per word sequence, the stream time each kept word became final (for teaching live-like
        windows: what the classifier knew at a time t inside a sub-task)."""
        self.watermark: dict[tuple[str, Level, str], float] = {}
        self.ended_arms: set[str] = set()
        self.ended_levels: set[tuple[str, Level]] = set()
        self.arms: set[str] = set()
        self.segments: list[_Segment] = []
        self.kept_from = -np.inf
        """Words ending before this stream time may have been dropped (pruning)."""
        self.pinned_from = np.inf
        """Words ending at or after this stream time are kept (a window waiting to be taught)."""
        self.task_ended = False
        self.now = 0.0
        self._issued = 0
        self._added = 0
        self.last_final: Belief | None = None
        self.ledgers: dict[str, WordLedger] = {}
        """Per arm, which of the stream's numbered words arrived (live/join.py)."""
        self.blind_until = -np.inf
        """Windows starting before this stream time overlap lost words (a late join)."""
        self._ordered = True
        """Every axis sequence has non-decreasing starts and ends (lets windows bisect)."""
        self._axis_memo = AxisMemo()
        """This stream's running-window compact features per axis (grammar/encoding/axes.py):
        owned here, passed to the predict calls of a model that takes one (`takes_axis_memo`)."""

    # --- input -------------------------------------------------------------------------------
    def add_words(
        self,
        arm: str,
        words: Iterable[Word],
        now: float | None = None,
        level: Level | None = None,
        seq_end: int = 0,
    ) -> None:
        """Add final words of `arm`; `now` is the stream time of the sample that finalised them.

        `level` and `seq_end` (Words.seq_end) tell the word ledger how far that level's topic
        has delivered; an empty list with them only moves the ledger on.
        """
        words = list(words)
        ledger = self.ledgers.get(arm)
        if ledger is None:
            ledger = self.ledgers[arm] = WordLedger()
        ledger.add(words, self.now if now is None else now, level, seq_end)
        if not words:
            return
        self.arms.add(arm)
        for w in words:
            seq = (
                self.words.words.setdefault(w.arm, {})
                .setdefault(w.level, {})
                .setdefault(w.axis, [])
            )
            if seq and (w.start < seq[-1].start or w.end < seq[-1].end):
                self._ordered = False
            seq.append(w)
            key = (w.arm, w.level, w.axis)
            self.arrivals.setdefault(key, []).append(max(self.now if now is None else now, w.end))
            if w.end > self.watermark.get(key, -np.inf):
                self.watermark[key] = w.end
            self.now = max(self.now, w.end)
            self._added += 1
        if now is not None:
            self.now = max(self.now, now)
        if self.mode == "window" and self._added > 2000:
            self._prune(self.now - max(self.window_s, self.history_s))

    def add_wrench(self, arm: str, blocks: Sequence[WrenchBlock]) -> None:
        """Add `arm`'s wrench blocks that closed since its previous ones (in time order)."""
        if blocks:
            self.wrench.setdefault(arm, WrenchTrack()).extend(blocks)

    def end_of_stream(self, arm: str, level: Level | None = None) -> None:
        """`arm`'s stream finished on `level` (None: on every level): its words there are final."""
        self.arms.add(arm)
        if arm in self.ledgers:
            self.ledgers[arm].end(level)
        for lv in LEVELS if level is None else (level,):
            self.ended_levels.add((arm, lv))
        if all((arm, lv) in self.ended_levels for lv in LEVELS):
            self.ended_arms.add(arm)

    def phase(self, name: str, t: float) -> bool:
        """A sub-task event at stream time `t`; returns False for names it does not know."""
        if name in self.end_phases:
            if self.segments and self.segments[-1].end is None:
                self.segments[-1].end = t
            self.task_ended = True
            self.now = max(self.now, t)
            return True
        if self.subtasks and name not in self.subtasks:
            return False
        if self.segments and self.segments[-1].end is None:
            self.segments[-1].end = t
        self.segments.append(_Segment(name, t))
        self.now = max(self.now, t)
        return True

    def account_losses(self) -> int:
        """Words of the stream proven lost since the last call (live/join.py WordLedger).

        A classifier that joined a running stream (or lost messages) misses words; a window that
        starts before the stream time those words may reach is judged UNKNOWN (`Belief.blind`),
        so the sub-task under way is unknown until the next boundary and no verdict rests on
        part of its words.
        """
        new = sum(ledger.settle() for ledger in self.ledgers.values())
        if new:
            self.blind_until = max(ledger.blind_until for ledger in self.ledgers.values())
        return new

    # --- output ------------------------------------------------------------------------------
    def classify(self, start: float, end: float, phase: str = "", final: bool = False) -> Belief:
        """Belief over the words overlapping [start, end] (UNKNOWN without words or model)."""
        if start < self.blind_until:
            probs = (0.0,) * len(self.classes)
            return Belief(
                UNKNOWN, self.classes, probs, start, end, self.mode, phase, final, blind=True
            )
        if self.model is None:
            n = sum(
                1
                for lv in self.words.words.values()
                for ws in lv.values()
                for seq in ws.values()
                for w in seq
                if w.end >= start and w.start <= end
            )
            return Belief(UNKNOWN, (), (), start, end, self.mode, phase, final, n)
        sample = window_sample(
            self.words, start, end, phase, self.trial, self._ordered, self.wrench
        )
        n = sum(
            len(seq)
            for lv in sample.words.words.values()
            for ws in lv.values()
            for seq in ws.values()
        )

        def belief(subtask: str, probabilities: tuple[float, ...]) -> Belief:
            return Belief(
                subtask, self.classes, probabilities, start, end, self.mode, phase, final, n
            )

        if self.model is None or n == 0:
            return belief(UNKNOWN, (0.0,) * len(self.classes))
        # a running window goes to the model's live head when it has one (learn/live.py); the
        # optional members (head, memo) are looked up, so the model is duck-typed from here
        model: Any = (
            self.model.head(final, self.mode) if hasattr(self.model, "head") else self.model
        )
        wrench = getattr(model, "reads_wrench", False)
        if not final and wrench and not self._wrench_evidence(start, end):
            return belief(UNKNOWN, (0.0,) * len(self.classes))  # no wrench of its own yet
        memo = {"memo": self._axis_memo} if getattr(model, "takes_axis_memo", False) else {}
        from sklearn import config_context  # loaded with the model; segmenter_node needs none

        try:
            # one sample at a time: scikit-learn's per-call checks cost more than the prediction
            # (the features are finite by construction); only for these calls, not globally
            with config_context(assume_finite=True, skip_parameter_validation=True):
                proba = self._in_class_order(model, model.predict_proba_samples([sample], **memo))
                if final:
                    # a verdict is the model's own prediction (as offline evaluation uses it),
                    # which for a probabilistic SVM need not be the arg-max of its probabilities
                    verdict = str(model.predict_samples([sample], **memo)[0])
                else:
                    verdict = self.classes[int(np.argmax(proba))]  # live: one model call
        except Exception as exc:  # a bad model must not stop the node
            self.last_error = f"{type(exc).__name__}: {exc}"
            return belief(UNKNOWN, (0.0,) * len(self.classes))
        return belief(verdict, tuple(float(p) for p in proba))

    def _wrench_evidence(self, start: float, end: float) -> bool:
        """Some arm has a wrench block in the window beside its baseline (the first 50-100 ms
        of a window read only words and a zero departure: no evidence, the state stays)."""
        return any(track.evidence(start, end) for track in self.wrench.values())

    def _in_class_order(self, head: Any, proba: Any) -> np.ndarray:
        """A head's probabilities of one window in the model's class order (a head trained on
        windows that lacked a sub-task has no column for it: 0)."""
        row: np.ndarray = np.asarray(proba)[0]
        names = [str(c) for c in getattr(head, "classes_", self.classes)]
        if names == list(self.classes):
            return row
        out = np.zeros(len(self.classes))
        for name, p in zip(names, row, strict=True):
            if name in self.classes:
                out[self.classes.index(name)] = p
        return out

    def window(self) -> tuple[float, float, str]:
        """(start, end, phase) of the current window."""
        if self.mode == "window":
            return max(0.0, self.now - self.window_s), self.now, ""
        if self.segments and self.segments[-1].end is None:
            seg = self.segments[-1]
            return seg.start, max(self.now, seg.start), seg.phase
        if self.segments:
            seg = self.segments[-1]
            return seg.start, seg.end if seg.end is not None else self.now, seg.phase
        return 0.0, self.now, ""

    def current(self) -> Belief:
        """The belief about the running window (after the task ended: the last verdict)."""
        if (
            self.mode == "boundary"
            and self.task_ended
            and self.last_final is not None
            and self._issued >= len(self.segments)
        ):
            return replace(self.last_final, final=False)
        start, end, phase = self.window()
        return self.classify(start, end, phase)

    def complete(self, end: float) -> bool:
        """Every word overlapping times up to `end` is final (each arm reached it or ended) and
        none is missing that may still arrive."""
        if any(ledger.has_gap for ledger in self.ledgers.values()):
            return False
        return self._complete(end)

    def last_subtask(self) -> tuple[str, float, float] | None:
        """(phase, start, end) of the sub-task that ended last in this stream, if any."""
        for seg in reversed(self.segments):
            if seg.end is not None:
                return seg.phase, seg.start, seg.end
        return None

    def _complete(self, end: float) -> bool:
        """Every word overlapping times up to `end` is final (each arm reached it or ended)."""
        if not self.arms:
            return self.task_ended
        for arm in self.arms:
            if arm in self.ended_arms:
                continue
            for level in LEVELS:
                if (arm, level) in self.ended_levels:
                    continue
                for axis in AXES:
                    if self.watermark.get((arm, level, axis), -np.inf) < end:
                        return False
        return True

    def take_finals(self) -> list[Belief]:
        """Final verdicts of closed sub-tasks whose words are all final (each issued once).

        None while a word is missing that may still arrive or be proven lost (a verdict must
        not rest on part of a sub-task's words; call `account_losses` first).
        """
        out: list[Belief] = []
        if any(ledger.has_gap for ledger in self.ledgers.values()):
            return out
        while self._issued < len(self.segments):
            seg = self.segments[self._issued]
            if seg.end is None or not self._complete(seg.end):
                break
            out.append(self.classify(seg.start, seg.end, seg.phase, final=True))
            self.last_final = out[-1]
            self._issued += 1
        if out:
            keep_from = out[-1].end
            if self._issued < len(self.segments):
                keep_from = min(keep_from, self.segments[self._issued].start)
            if self.history_s > 0:  # teaching: the last finished sub-task and recent history
                keep_from = min(keep_from, out[-1].start, self.now - self.history_s)
            self._prune(keep_from)
        return out

    @property
    def finished(self) -> bool:
        """The task ended and every sub-task verdict was issued."""
        return self.task_ended and self._issued >= len(self.segments) and self._complete(self.now)

    def _prune(self, before: float) -> None:
        """Drop words that end before `before` (no later window can overlap them)."""
        before = min(before, self.pinned_from)
        self.kept_from = max(self.kept_from, before)
        for track in self.wrench.values():
            track.drop_before(before)
        for arm, per_level in self.words.words.items():
            for level, per_axis in per_level.items():
                for axis, seq in per_axis.items():
                    if seq and seq[0].end < before:
                        key = (arm, level, axis)
                        kept = [
                            (w, a)
                            for w, a in zip(seq, self.arrivals[key], strict=False)
                            if w.end >= before
                        ]
                        per_axis[axis] = [w for w, _ in kept]
                        self.arrivals[key] = [a for _, a in kept]
        self._added = 0

    def words_final_by(self, t: float, start: float = -np.inf) -> TrialWords:
        """The kept words overlapping [start, t] that were final at stream time `t` (what a
        running window from `start` saw at `t`)."""
        out = TrialWords(name=self.trial)
        for arm, per_level in self.words.words.items():
            for level, per_axis in per_level.items():
                for axis, seq in per_axis.items():
                    arrived = self.arrivals[(arm, level, axis)]
                    out.words.setdefault(arm, {}).setdefault(level, {})[axis] = [
                        w for w, a in zip(seq, arrived, strict=False) if a <= t and w.end >= start
                    ]
        return out

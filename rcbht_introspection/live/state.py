"""/task_state from successive beliefs: a new sub-task becomes the state only when it is confident.

A planner acts on every /task_state change, so the state moves to a new sub-task only when the
running belief's leading class passes every test of `TaskStateConfig` (probability, log ratio
over the current state, accumulated log-odds, hold). Before the first confident belief the state is
"unknown"; a belief without enough evidence (a window of fewer than `min_words` words, e.g. right
after a sub-task event or at the start of a new stream) keeps the state; a blind belief (words
proven lost, live/join.py) makes it "unknown" at once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from rcbht_introspection.config_files import described
from rcbht_introspection.errors import InputError
from rcbht_introspection.live.belief import UNKNOWN, Belief

TINY = 1e-9
"""Floor of a probability in a log ratio (a class the model rules out entirely)."""


@dataclass(frozen=True)
class TaskStateConfig:
    """When a new believed sub-task becomes /task_state (classifier_node parameters `state.*`)."""

    min_probability: float = described(
        0.6, "the new sub-task's probability must be at least this (0: any)"
    )
    min_log_ratio: float = described(
        0.0,
        "... and its log ratio over the current state's probability at least this "
        "(0: leading is enough; no test while the state is unknown)",
    )
    evidence_bound: float = described(
        0.0,
        "sequential test: the log-odds log(p/(1-p)) of the leading sub-task, summed over the "
        "successive beliefs it leads, must reach this (0: off)",
    )
    min_words: int = described(
        3,
        "... and its window must hold at least this many words (a window of a few words is "
        "over-confident; 0: any)",
    )
    hold_s: float = described(
        0.0,
        "... and the belief must have passed the tests for this long (stream seconds; 0: at once)",
    )


def check_task_state(config: TaskStateConfig) -> None:
    """Ranges of the fields; InputError names the field."""
    checks = (
        ("min_probability", 0 <= config.min_probability <= 1, "[0, 1]"),
        ("min_log_ratio", 0 <= config.min_log_ratio <= 50, "[0, 50]"),
        ("evidence_bound", 0 <= config.evidence_bound <= 1000, "[0, 1000]"),
        ("min_words", 0 <= config.min_words <= 100000, "[0, 100000]"),
        ("hold_s", 0 <= config.hold_s <= 10, "[0, 10]"),
    )
    for name, ok, bounds in checks:
        if not ok:
            raise InputError(f"must be in {bounds}, got {getattr(config, name)}", field=name)


class StateFilter:
    """/task_state of one classifier: `update` with each running belief, `new_stream` per stream."""

    def __init__(self, config: TaskStateConfig | None = None) -> None:
        self.config = config if config is not None else TaskStateConfig()
        check_task_state(self.config)
        self.state = UNKNOWN
        self._reported = UNKNOWN
        self._candidate: str | None = None
        self._since = 0.0
        self._evidence = 0.0

    def confident(self, belief: Belief) -> bool:
        """The belief's sub-task passes the probability and log-ratio tests (not the sequential
        test or the hold, which need the beliefs before it)."""
        p = _probability(belief, belief.subtask)
        if p < self.config.min_probability:
            return False
        if self.state == UNKNOWN or self.config.min_log_ratio <= 0:
            return True
        ratio = math.log(max(p, TINY) / max(_probability(belief, self.state), TINY))
        return ratio >= self.config.min_log_ratio

    def update(self, t: float, belief: Belief) -> bool:
        """Feed the running belief at stream time `t`; True when /task_state changed."""
        if belief.blind:
            self._drop()
            self.state = UNKNOWN
        elif belief.subtask in (UNKNOWN, self.state) or belief.n_words < self.config.min_words:
            self._drop()  # no evidence (an empty window) or too little keeps the state
        elif not self.confident(belief):
            self._drop()
        else:
            if belief.subtask != self._candidate:
                self._candidate, self._since, self._evidence = belief.subtask, t, 0.0
            p = min(max(_probability(belief, belief.subtask), TINY), 1 - TINY)
            self._evidence += math.log(p / (1 - p))
            if (
                self.config.evidence_bound <= 0 or self._evidence >= self.config.evidence_bound
            ) and t - self._since >= self.config.hold_s:
                self.state = belief.subtask
                self._drop()
        changed = self.state != self._reported
        self._reported = self.state
        return changed

    def new_stream(self) -> None:
        """A new stream: its first sub-task boundary, where the state, as at any other, stays
        until a confident belief (a pending candidate of the old stream is dropped)."""
        self._drop()

    def _drop(self) -> None:
        self._candidate, self._evidence = None, 0.0


def _probability(belief: Belief, subtask: str) -> float:
    """The belief's probability of `subtask` (1 for the believed one of a model without
    probabilities, 0 for a name it does not know)."""
    if subtask in belief.classes and belief.probabilities:
        return float(belief.probabilities[belief.classes.index(subtask)])
    return 1.0 if subtask == belief.subtask and not belief.probabilities else 0.0

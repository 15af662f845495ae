"""The mismatch signal: the classifier's verdict on a finished sub-task names another sub-task
than the one the state machine commanded, with confidence.

On the simulator's failures this is what the belief already knows (a jammed or misaligned part
does not look like a nominal insertion), but only once the sub-task ended: it is the verifier's
late witness beside the early novelty and timing signals. Live, verifier_node reads the final
beliefs on rcbht/belief; offline, the trial is replayed through the classifier as the node runs
it (live/replay.py) and each final verdict applies from the stream time it was issued.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from rcbht_introspection.io.trial import Trial
from rcbht_introspection.live.belief import UNKNOWN, Belief, SampleClassifier
from rcbht_introspection.live.replay import node_stream, replay_beliefs
from rcbht_introspection.taxonomy.stream import ArmStream
from rcbht_introspection.verify.config import VerifyConfig
from rcbht_introspection.verify.detector import Detection, detection_of

MISMATCH = "mismatch"
"""The signal's name in verdicts (beside the detector's signals)."""


@dataclass(frozen=True)
class Contradiction:
    """A final verdict that contradicts its commanded sub-task."""

    time: float
    """Stream time from which it is known (the verdict's issue time; live: its arrival)."""
    start: float
    """Start of the contradicted sub-task: the onset estimate of an alarm it raises."""
    phase: str
    subtask: str
    probability: float
    """The classifier's probability of `subtask`."""


def contradiction_of(
    belief: Belief, known_at: float, min_probability: float
) -> Contradiction | None:
    """The contradiction `belief` states, or None: it must be a final verdict on a commanded
    sub-task the model knows, naming another sub-task with probability above `min_probability`."""
    if not belief.final or not belief.phase or belief.subtask in (UNKNOWN, belief.phase):
        return None
    if belief.phase not in belief.classes:  # a model that cannot name it cannot contradict it
        return None
    p = dict(zip(belief.classes, belief.probabilities, strict=False)).get(belief.subtask, 0.0)
    if p <= min_probability:
        return None
    return Contradiction(known_at, belief.start, belief.phase, belief.subtask, float(p))


def trial_contradictions(
    trial: Trial,
    model: SampleClassifier,
    stream_factory: Callable[[str], ArmStream],
    min_probability: float,
) -> list[Contradiction]:
    """The contradictions classifier_node states for `trial` (boundary mode), in issue order,
    that verifier_node can use: not the verdict on the sub-task the end event closes, which is
    issued once the stream has ended (the verifier's stream is over by then)."""
    [streamed] = node_stream([trial], stream_factory)
    [replay] = replay_beliefs([streamed], model, "boundary")
    windows = streamed.subtask_windows()
    last_end = windows[-1][2] if windows else float("inf")
    found = (
        contradiction_of(b, t, min_probability)
        for b, t in zip(replay.finals, replay.final_times, strict=True)
        if b.end < last_end - 1e-9
    )
    return [c for c in found if c is not None]


def mismatch_scores(
    times: np.ndarray, contradictions: Sequence[Contradiction], min_probability: float
) -> np.ndarray:
    """The mismatch signal over its threshold at each tick: the largest probability /
    min_probability of the contradictions known by then (0 before the first). Latched, as the
    alarm is."""
    out = np.zeros(len(times))
    for c in contradictions:
        out[times >= c.time - 1e-9] = np.maximum(
            out[times >= c.time - 1e-9], c.probability / min_probability
        )
    return out


def with_mismatch(
    detection: Detection, contradictions: Sequence[Contradiction], config: VerifyConfig
) -> Detection:
    """`detection` with the mismatch signal as one more column (the documented rule: an alarm
    when any signal is over its threshold). An alarm the mismatch raises has the contradicted
    sub-task's start as its onset estimate: its evidence is that whole sub-task."""
    min_p = config.mismatch_min_probability
    column = mismatch_scores(detection.times, contradictions, min_p)
    normalised = np.column_stack([detection.normalised, column])
    signals = (*detection.signals, MISMATCH)
    out = detection_of(detection.times, normalised, signals, config.onset_fraction)
    if out.alarm is not None and out.alarm_signal == MISMATCH:
        return replace(out, onset=mismatch_onset(contradictions, out.alarm, min_p))
    return out


def mismatch_onset(
    contradictions: Sequence[Contradiction], at: float, min_probability: float
) -> float | None:
    """Start of the earliest contradicted sub-task among those known at `at`."""
    starts = [
        c.start for c in contradictions if c.time <= at + 1e-9 and c.probability > min_probability
    ]
    return min(starts) if starts else None

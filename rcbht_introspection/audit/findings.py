"""A finding of the audit: what, where, how strong, and what to do about it."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

ACTIONS: dict[str, str] = {
    "convention_change": "relabel: move this boundary on one side to where the other side puts "
    "it, so both use one convention; or train and evaluate on one side only",
    "duration_shift": "check the labels after the change; if the procedure changed there, split "
    "the set (train and evaluate each part, or across parts)",
    "duration_outlier": "look at these trials (a retry, a pause, a state published early or "
    "late): relabel them or leave them out",
    "session": "tare: subtract each trial's free-motion level (segmenter intake tare_at_start) "
    "or zero the sensor before each session; if the sensor or its mounting changed, run "
    "`rcbht calibrate` on this session; evaluate grouped by session (train on some, test on "
    "the others)",
    "session_change": "split by session at this trial (evaluate across sessions), or tare each "
    "trial at its free-motion level (segmenter intake tare_at_start); recalibrate if the sensor "
    "changed",
    "frozen_sensor": "check the sensor and its driver; cut the frozen stretch or leave the trial "
    "out (a frozen stretch reads as contact-free and drags a calibration's noise floor to 0)",
    "dropped_stamps": "none if they are re-sent samples (same values); otherwise the stamps are "
    "coarser than the rate: read with --repeated-stamps spread or fix the driver's stamps",
    "gaps": "samples were lost in transport or logging (check the recorder's queue and CPU); "
    "the words jump over a gap, so leave long ones out",
    "sampling_rate": "the taxonomy's windows count samples: resample to one rate (bag import "
    "--rate) or calibrate a profile for each rate (rcbht calibrate)",
    "dropped_state_times": "the state log has times after the recording or out of order: the "
    "sub-task each dropped time started is missing from its trial; fix the log or relabel",
    "incomplete_trial": "the trial ends before its task does: its last sub-task is left out of "
    "the durations; check its state events, or leave it out of training",
    "unreadable": "fix the file named (the rest of the set was audited without it)",
}
"""What to do about each kind of finding (docs/audit.md)."""


@dataclass(frozen=True)
class Finding:
    """One problem of the data set. `trials` and `subtasks` say where; `between` names the last
    trial before and the first after a change; `strength` holds the statistics."""

    kind: str
    message: str
    trials: tuple[str, ...] = ()
    subtasks: tuple[str, ...] = ()
    between: tuple[str, str] | None = None
    strength: dict[str, Any] = field(default_factory=dict)
    detail: dict[str, Any] = field(default_factory=dict)
    evidence: str = ""
    """More support for the finding in words (the classifier check of a change)."""

    @property
    def action(self) -> str:
        return ACTIONS[self.kind]

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "message": self.message,
            "trials": list(self.trials),
            "subtasks": list(self.subtasks),
            "between": list(self.between) if self.between else None,
            "strength": self.strength,
            "detail": self.detail,
            "evidence": self.evidence,
            "action": self.action,
        }


def span(names: list[str] | tuple[str, ...]) -> str:
    """'first..last' of trial names, the last without the start it shares with the first up to
    a separator ('20121127-HIROSA-S-01..21'); one name alone when they are the same."""
    if not names:
        return ""
    first, last = names[0], names[-1]
    if first == last:
        return first
    common = 0
    for a, b in zip(first, last, strict=False):
        if a != b:
            break
        common += 1
    cut = max((i + 1 for i in range(common) if not first[i].isalnum()), default=0)
    return f"{first}..{last[cut:]}"


def sigmas(value: float) -> str:
    """A shift in robust sigmas, signed."""
    return f"{value:+.1f} sigma" if abs(value) < 1e4 else f"{value:+.3g} sigma"


def seconds(value: float) -> str:
    """A duration for a message: ms below 0.1 s, else s."""
    return f"{value * 1000:.3g} ms" if value < 0.1 else f"{value:.3g} s"

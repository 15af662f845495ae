"""The word records shared by all three RCBHT levels: primitive, composition (MC), behavior (LLB)."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

AXES: tuple[str, ...] = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")

PRIMITIVE_LABELS: tuple[str, ...] = (
    "bpos", "mpos", "spos", "bneg", "mneg", "sneg", "cons", "pimp", "nimp", "none",
)  # fmt: skip
"""Primitive labels in the original integer order (1..10); spec 2 and 3 use these indices."""
COMPOSITION_LABELS: tuple[str, ...] = ("a", "i", "d", "k", "pc", "nc", "c", "u", "n", "z")
"""MC labels: adjustment, increase, decrease, constant, pos/neg contact, contact, unstable, noisy, none."""
BEHAVIOR_LABELS: tuple[str, ...] = ("FX", "CT", "PS", "PL", "AL", "SH", "U", "N")
"""LLB labels: fixed, contact, push, pull, align, shift, unstable, noise."""


class Level(str, Enum):  # noqa: UP042 - StrEnum changes str() of members, which outputs print
    """The three levels of the taxonomy, lowest first."""

    PRIMITIVE = "primitive"
    COMPOSITION = "composition"
    BEHAVIOR = "behavior"

    @property
    def labels(self) -> tuple[str, ...]:
        """The label vocabulary of this level, in the original integer order."""
        return {
            Level.PRIMITIVE: PRIMITIVE_LABELS,
            Level.COMPOSITION: COMPOSITION_LABELS,
            Level.BEHAVIOR: BEHAVIOR_LABELS,
        }[self]


LEVELS: tuple[Level, ...] = (Level.PRIMITIVE, Level.COMPOSITION, Level.BEHAVIOR)


@dataclass(frozen=True)
class Word:
    """One word of one axis: its label, the time span it covers and its level's features.

    `start`/`end` are the span used for sub-task splitting (primitive Start/Finish; MC and LLB
    t1Start/t2End). `features` holds the level's numeric record fields under their original
    keys (e.g. 'Gradient', 'Average Val', 't1End'), so the original text format round-trips.
    `seq` is the per-stream sequence number (batch words are numbered too: batch is a stream).
    """

    axis: str
    level: Level
    label: str
    start: float
    end: float
    features: dict[str, float] = field(default_factory=dict, compare=True)
    arm: str = "R"
    seq: int = field(default=0, compare=False)
    sublabels: tuple[str, ...] = ()
    """The two lower-level labels an MC or LLB was composed from ('Label 1', 'Label 2')."""

    @property
    def duration(self) -> float:
        return self.end - self.start


@dataclass
class TrialWords:
    """All words of one trial: words[arm][level][axis] is the time-ordered list."""

    name: str
    words: dict[str, dict[Level, dict[str, list[Word]]]] = field(default_factory=dict)

    def axis_words(self, arm: str, level: Level, axis: str) -> list[Word]:
        """The words of one arm, level and axis (empty if absent)."""
        return self.words.get(arm, {}).get(level, {}).get(axis, [])

    def add(self, word: Word) -> None:
        """Append a word to its arm/level/axis list."""
        per_level = self.words.setdefault(word.arm, {}).setdefault(word.level, {})
        per_level.setdefault(word.axis, []).append(word)

    @property
    def arms(self) -> tuple[str, ...]:
        return tuple(sorted(self.words))

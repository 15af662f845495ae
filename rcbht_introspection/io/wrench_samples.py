"""The wrench samples of an imported bag: the stamp policy per arm, the cut to the trial's phases,
and one clock for several arms (their own stamps when they agree, else a resampled grid).

Stamp policy (docs/bags.md, "Importing bags from another robot"), in receive order: a zero stamp
is unset and dropped; a stamp equal to the previous kept one is dropped (the first is kept); a
stamp before the previous kept one is dropped. Each is counted.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rcbht_introspection.errors import InputError

_NS = 10**9
SAME_STAMP_NS = 1000
"""Arms whose stamps differ by no more than this share one clock (as in io/bags.py's reader)."""


@dataclass(frozen=True)
class ArmCounts:
    """The wrench samples of one arm: read, dropped by the stamp policy, cut, kept."""

    source: str
    messages: int
    unset: int
    """Zero stamps (unset): dropped."""
    repeated: int
    """Stamps equal to the previous kept stamp: dropped (the first is kept)."""
    decreasing: int
    """Stamps before the previous kept stamp: dropped."""
    before_first_phase: int
    after_end: int
    kept: int
    """Samples of this arm in the trial (before any resampling)."""


class WrenchSamples:
    """The samples of one arm in receive order, under the stamp policy."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.stamps: list[int] = []
        self.values: list[tuple[float, ...]] = []
        self.messages = self.unset = self.repeated = self.decreasing = 0

    def add(self, stamp: int, wrench: Any) -> None:
        """Take one geometry_msgs/Wrench with its stamp (ns), or count why it is dropped."""
        self.messages += 1
        if stamp == 0:
            self.unset += 1
        elif self.stamps and stamp == self.stamps[-1]:
            self.repeated += 1
        elif self.stamps and stamp < self.stamps[-1]:
            self.decreasing += 1
        else:
            self.stamps.append(stamp)
            f, m = wrench.force, wrench.torque
            self.values.append((f.x, f.y, f.z, m.x, m.y, m.z))

    @property
    def last(self) -> int | None:
        """Stamp of the last kept sample."""
        return self.stamps[-1] if self.stamps else None

    def cut(
        self, start_ns: int, end_ns: int | None, arm: str, bag: Path
    ) -> tuple[np.ndarray, np.ndarray, ArmCounts]:
        """(stamps, (n, 6) values) from start_ns to end_ns inclusive (None: the last sample)."""
        t = np.asarray(self.stamps, dtype=np.int64)
        inside = (t >= start_ns) & (t <= (t[-1] if end_ns is None else end_ns))
        kept = int(inside.sum())
        if not kept:
            raise InputError(
                f"no samples of arm {arm} between the first and the end phase",
                bag,
                field=self.source,
            )
        before = int(np.count_nonzero(t < start_ns))
        counts = ArmCounts(
            self.source,
            self.messages,
            self.unset,
            self.repeated,
            self.decreasing,
            before,
            len(t) - before - kept,
            kept,
        )
        return t[inside], np.asarray(self.values, dtype=np.float64)[inside], counts


def align(
    samples: Mapping[str, tuple[np.ndarray, np.ndarray]], rate_hz: float | None, bag: Path
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """One stamp column (ns) for every arm: the arms' own when they agree; with `rate_hz`, a grid
    at that rate over the span every arm covers, each axis interpolated linearly."""
    arms = list(samples)
    if rate_hz is None:
        ref = samples[arms[0]][0]
        for arm in arms[1:]:
            other = samples[arm][0]
            if len(other) != len(ref) or np.any(np.abs(other - ref) > SAME_STAMP_NS):
                raise InputError(
                    f"arms {arms[0]} and {arm} have different stamps: give --rate HZ to resample them onto one clock",
                    bag,
                )
        return ref, {arm: v for arm, (_, v) in samples.items()}
    start = max(int(s[0]) for s, _ in samples.values())
    stop = min(int(s[-1]) for s, _ in samples.values())
    if stop <= start:
        raise InputError("the arms' samples do not overlap in time", bag, field="--rate")
    step = _NS / rate_hz
    grid = start + np.rint(np.arange(int((stop - start) // step) + 1) * step).astype(np.int64)
    x = (grid - start) / _NS
    values = {}
    for arm, (s, v) in samples.items():
        xp = (s - start) / _NS
        values[arm] = np.column_stack([np.interp(x, xp, v[:, k]) for k in range(v.shape[1])])
    return grid, values

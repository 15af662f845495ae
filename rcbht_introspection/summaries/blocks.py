"""Block means of one arm's wrench: the summary the sub-task estimator reads beside the words.

Stream time is cut into blocks of BLOCK_S seconds on a fixed grid (block k holds the samples with
floor(t / BLOCK_S) == k). A block is closed by the arm's first sample past it, so at stream time t
every block ending at or before t is known, live as offline. A block without samples is skipped;
the partial block at the end of a stream is never closed. The segmenter sends the closed blocks
with its words (live/segmenter.py), and training computes them with the same class, so the live
and the offline summaries are the same numbers.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from rcbht_introspection.io.trial import Trial

BLOCK_S = 0.05
"""Block length (s): 20 summaries per second, above the sub-task scale and below the words'."""
N_AXES = 6


@dataclass(frozen=True)
class WrenchBlock:
    """The mean wrench (Fx, Fy, Fz, Mx, My, Mz) of one arm's samples in (end - BLOCK_S, end]."""

    end: float
    samples: int
    mean: tuple[float, ...]


class BlockMeans:
    """Streaming block means of one arm: `push` each accepted sample, `take` the closed blocks."""

    __slots__ = ("_closed", "_count", "_index", "_sums", "period")

    def __init__(self, period: float = BLOCK_S) -> None:
        self.period = period
        self._index: int | None = None
        self._sums = [0.0] * N_AXES
        self._count = 0
        self._closed: list[WrenchBlock] = []

    def push(self, t: float, wrench: Sequence[float]) -> None:
        """Add one sample at stream time `t` (non-decreasing); closes the block before it."""
        index = math.floor(t / self.period)
        if index != self._index:
            self._close()
            self._index = index
        sums = self._sums
        for i in range(N_AXES):
            sums[i] += wrench[i]
        self._count += 1

    def _close(self) -> None:
        if self._count and self._index is not None:
            n = self._count
            mean = tuple(s / n for s in self._sums)
            self._closed.append(WrenchBlock((self._index + 1) * self.period, n, mean))
        self._sums = [0.0] * N_AXES
        self._count = 0

    def take(self) -> list[WrenchBlock]:
        """The blocks closed since the last call, in time order."""
        closed, self._closed = self._closed, []
        return closed


class WrenchTrack:
    """An arm's closed blocks as arrays (end times, means), growing live and prunable."""

    def __init__(self) -> None:
        self.ends: NDArray[np.float64] = np.empty(0)
        self.means: NDArray[np.float64] = np.empty((0, N_AXES))
        self._size = 0
        self.origin: NDArray[np.float64] | None = None
        """The mean of the earliest block this track was given (kept by drop_before): the
        stream's level at its start, free motion before the task's contacts."""
        self._origin_end = math.inf

    def __len__(self) -> int:
        return self._size

    def extend(self, blocks: Sequence[WrenchBlock]) -> None:
        """Add blocks; arrays grow by doubling, views of old ones stay valid. Blocks come in time
        order, except from a straggling message (a batch's first message on another topic than
        the last one's): those are put in place, so the ends stay sorted."""
        if not blocks:
            return
        first = min(blocks, key=lambda b: b.end)
        if first.end < self._origin_end:
            self.origin, self._origin_end = np.asarray(first.mean, dtype=float), first.end
        late = self._size and blocks[0].end <= self.ends[self._size - 1]
        need = self._size + len(blocks)
        if need > len(self.ends):
            capacity = max(need, 2 * len(self.ends), 64)
            ends, means = np.empty(capacity), np.empty((capacity, N_AXES))
            ends[: self._size] = self.ends[: self._size]
            means[: self._size] = self.means[: self._size]
            self.ends, self.means = ends, means
        for i, block in enumerate(blocks, start=self._size):
            self.ends[i] = block.end
            self.means[i] = block.mean
        self._size = need
        if late:
            order = np.argsort(self.ends[:need], kind="stable")
            self.ends[:need], self.means[:need] = self.ends[order], self.means[order]

    def drop_before(self, t: float) -> None:
        """Forget blocks that no window starting at or after `t` reads (its baseline is kept)."""
        keep = max(0, bisect_right(self.ends[: self._size], t) - 1)
        if keep:
            self.ends = self.ends[keep : self._size].copy()
            self.means = self.means[keep : self._size].copy()
            self._size -= keep

    def window(self, start: float, end: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(baseline mean, means of the blocks ending in (start, end]): the baseline is the last
        block ending at or before `start` (the level as the window began), else the first."""
        ends = self.ends[: self._size]
        lo = bisect_right(ends, start)
        hi = bisect_right(ends, end)
        if self._size == 0:
            return np.zeros(N_AXES), np.empty((0, N_AXES))
        base = self.means[lo - 1] if lo > 0 else self.means[0]
        return base, self.means[lo:hi]

    def evidence(self, start: float, end: float) -> int:
        """Blocks of (start, end] beside the baseline `window` compares them with: 0 while the
        window has no wrench of its own yet (its only block is its baseline)."""
        ends = self.ends[: self._size]
        lo, hi = bisect_right(ends, start), bisect_right(ends, end)
        return max(0, hi - max(lo, 1))

    def until(self, t: float) -> WrenchTrack:
        """A copy holding the blocks ending at or before `t` (what a window ending at `t` reads;
        later growth or pruning of this track does not reach it)."""
        n = bisect_right(self.ends[: self._size], t)
        out = WrenchTrack()
        out.ends, out.means, out._size = self.ends[:n].copy(), self.means[:n].copy(), n
        if self._origin_end <= t:
            out.origin, out._origin_end = self.origin, self._origin_end
        return out

    @classmethod
    def of_blocks(cls, blocks: Sequence[WrenchBlock]) -> WrenchTrack:
        track = cls()
        track.extend(blocks)
        return track


def trial_tracks(trial: Trial, period: float = BLOCK_S) -> Mapping[str, WrenchTrack]:
    """Each arm's track of a recorded trial, computed by the live class (BlockMeans)."""
    out: dict[str, WrenchTrack] = {}
    # stream time as the segmenter computes it from the stamps of a trial bag (live/replay.py),
    # back on the trial's clock (its words and state times) when that does not start at 0
    ns = np.rint(np.asarray(trial.time, dtype=float) * 1e9).astype(np.int64)
    start = float(trial.time[0]) if len(ns) else 0.0
    times = ((ns - ns[0]) / 1e9 + start).tolist() if len(ns) else []
    for arm, wrench in trial.wrench.items():
        means = BlockMeans(period)
        for t, row in zip(times, np.asarray(wrench, dtype=float).tolist(), strict=True):
            means.push(t, row)
        out[arm] = WrenchTrack.of_blocks(means.take())
    return out

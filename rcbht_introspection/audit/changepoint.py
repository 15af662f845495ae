"""Changepoints in a sequence over trials: a rank scan with a permutation null.

The statistic of a sequence x_1..x_n (one or several channels) is the largest standardised rank
sum over every split into a first part of k values and a second of n - k (both at least
`min_segment`): with r the ranks of a channel centred on their mean and s2 their variance,
z_k = |r_1 + ... + r_k| / sqrt(k (n - k) s2 / (n - 1)), the Mann-Whitney statistic of the split
in standard units (exact under ties), maximised over k and over channels. Its null distribution
is that of the same maximum over random orders of the trials (the trials are exchangeable when
nothing changed), so the p-value is (1 + #{permuted >= observed}) / (1 + B) whatever the
distribution of the values. Ranks make it blind to a few outlying trials; the split is placed
where two medians fit the values best (least absolute deviations), which ranks cannot locate
sharply. Several changes are found by binary segmentation: each part of a significant split is
tested again.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

MIN_SEGMENT = 2
"""Fewest trials on either side of a split."""
_CHUNK = 2048
"""Permutations scanned at once (bounds the memory of the null to CHUNK x n x channels)."""


@dataclass(frozen=True)
class Change:
    """A significant split of a sequence: values [start, split) against [split, stop)."""

    start: int
    split: int
    stop: int
    statistic: float
    """Largest standardised rank sum (z) of the tested part."""
    p_value: float
    """Permutation p-value of the tested part, before any correction."""
    p_adjusted: float
    """p_value times the number of sequences tested together (Bonferroni), at most 1."""


def _as_channels(x: np.ndarray) -> np.ndarray:
    values = np.asarray(x, dtype=np.float64)
    return values[:, None] if values.ndim == 1 else values


def _centred_ranks(x: np.ndarray) -> np.ndarray:
    """(n, c) ranks of each channel (ties averaged), minus their mean."""
    from scipy.stats import rankdata

    ranks = np.asarray(rankdata(x, axis=0), dtype=np.float64)
    centred: NDArray[np.float64] = ranks - ranks.mean(axis=0)
    return centred


def scan(ranks: np.ndarray, min_segment: int = MIN_SEGMENT) -> np.ndarray:
    """Largest |standardised rank sum| over splits and channels of each (..., n, c) sequence of
    centred ranks; 0 for a channel whose values are all equal."""
    n = ranks.shape[-2]
    k = np.arange(min_segment, n - min_segment + 1, dtype=np.float64)[:, None]
    if len(k) == 0:
        return np.zeros(ranks.shape[:-2])
    s2 = np.mean(ranks**2, axis=-2, keepdims=True)  # (..., 1, c): the ranks are centred
    sums = np.cumsum(ranks, axis=-2)[..., min_segment - 1 : n - min_segment, :]
    var = k * (n - k) / (n - 1) * s2
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.where(var > 0, np.abs(sums) / np.sqrt(np.where(var > 0, var, 1.0)), 0.0)
    return np.asarray(z.max(axis=(-2, -1)))


def permutation_p(
    x: np.ndarray, permutations: int, rng: np.random.Generator, min_segment: int = MIN_SEGMENT
) -> tuple[float, float]:
    """(statistic, p-value) of the rank scan of `x` ((n,) or (n, c)) against `permutations`
    random orders of its rows."""
    ranks = _centred_ranks(_as_channels(x))
    observed = float(scan(ranks, min_segment))
    if observed <= 0.0:
        return 0.0, 1.0
    n = len(ranks)
    exceed = 0
    done = 0
    while done < permutations:
        size = min(_CHUNK, permutations - done)
        order = rng.permuted(np.tile(np.arange(n), (size, 1)), axis=1)
        null = scan(ranks[order], min_segment)
        exceed += int(np.count_nonzero(null >= observed * (1.0 - 1e-9)))
        done += size
    return observed, (1 + exceed) / (1 + permutations)


def best_split(x: np.ndarray, min_segment: int = MIN_SEGMENT) -> int:
    """The split k (first index of the second part) whose two medians fit `x` ((n,) or (n, c),
    channels already on a common scale) with the least total absolute deviation."""
    values = _as_channels(x)
    n = len(values)
    best, best_cost = min_segment, np.inf
    for k in range(min_segment, n - min_segment + 1):
        head, tail = values[:k], values[k:]
        cost = float(
            np.abs(head - np.median(head, axis=0)).sum()
            + np.abs(tail - np.median(tail, axis=0)).sum()
        )
        if cost < best_cost - 1e-12:
            best, best_cost = k, cost
    return best


@dataclass(frozen=True)
class WholeTest:
    """The test of the whole sequence, significant or not: how far from a change it is."""

    statistic: float
    p_value: float
    p_adjusted: float


@dataclass(frozen=True)
class Segmentation:
    changes: list[Change]
    whole: WholeTest | None
    """None: too few values to test (fewer than 2 x min_segment)."""


def find_changes(
    x: np.ndarray,
    alpha: float,
    permutations: int,
    seed: int | list[int],
    tests: int = 1,
    min_segment: int = MIN_SEGMENT,
    accept: Callable[[int, int, int], bool] | None = None,
) -> Segmentation:
    """Binary segmentation of `x` ((n,) or (n, c)): every split whose p-value times `tests`
    (Bonferroni over the sequences tested together) is at most `alpha`, and that `accept(start,
    split, stop)` keeps (e.g. an effect above the measurement's resolution), in order; and the
    test of the whole sequence.

    Each tested part draws its permutations from a generator seeded by (`seed`, start, stop),
    so the result does not depend on the order of the work."""
    values = _as_channels(x)
    seeds = [seed] if isinstance(seed, int) else list(seed)
    found: list[Change] = []
    whole: WholeTest | None = None
    todo = [(0, len(values))]
    while todo:
        start, stop = todo.pop()
        if stop - start < 2 * min_segment:
            continue
        rng = np.random.default_rng([*seeds, start, stop])
        part = values[start:stop]
        statistic, p = permutation_p(part, permutations, rng, min_segment)
        p_adjusted = min(1.0, p * tests)
        if start == 0 and stop == len(values):
            whole = WholeTest(statistic, p, p_adjusted)
        if p_adjusted > alpha:
            continue
        split = start + best_split(_robust_scaled(part), min_segment)
        if accept is not None and not accept(start, split, stop):
            continue
        found.append(Change(start, split, stop, statistic, p, p_adjusted))
        todo.extend([(start, split), (split, stop)])
    return Segmentation(sorted(found, key=lambda c: c.split), whole)


def _robust_scaled(x: np.ndarray) -> np.ndarray:
    """Channels divided by a step-insensitive spread: the median absolute successive difference
    (channels that never change are left as they are)."""
    if len(x) < 2:
        return x
    spread = np.median(np.abs(np.diff(x, axis=0)), axis=0)
    spread = np.where(spread > 0, spread, np.abs(x).max(axis=0))
    scaled: NDArray[np.float64] = x / np.where(spread > 0, spread, 1.0)
    return scaled


def robust_sigma(x: np.ndarray) -> float:
    """Spread of values as a normal sigma, robust to outliers: the larger of 1.4826 MAD and
    IQR / 1.349 (the second survives a majority of equal values); 0 for fewer than two."""
    values = np.asarray(x, dtype=np.float64)
    if len(values) < 2:
        return 0.0
    mad = 1.4826 * float(np.median(np.abs(values - np.median(values))))
    q1, q3 = np.percentile(values, [25, 75])
    return max(mad, float(q3 - q1) / 1.349)

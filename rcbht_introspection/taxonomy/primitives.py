"""Primitive layer (spec 2.1): regression segmentation, gradient labels, clean-up rules, calibration.

The segmenter is incremental: it is fed blocks of W samples and keeps, per axis, only the running
least-squares statistics of the open segment (merged block by block with Chan's pairwise update,
O(1) per window step and numerically stable). The batch engine feeds a whole trial as one array of
blocks, the streaming engine feeds one block whenever W samples have arrived: one implementation.

Records are plain lists in the original `statData` layout, [avg, max, min, start, finish, gradient,
label] with the label as its 1-based integer, so each rule reads like the spec.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from rcbht_introspection.taxonomy.config import TaxonomyConfig
from rcbht_introspection.taxonomy.words import AXES, PRIMITIVE_LABELS, Level, Word

AVG, MAX, MIN, START, FINISH, GRAD, LABEL = range(7)
"""Field indices of a primitive record (statData columns)."""
BPOS, MPOS, SPOS, BNEG, MNEG, SNEG, CONS, PIMP, NIMP, NONE = range(1, 11)
"""Primitive label integers (spec 2: bpos..none = 1..10)."""
POSITIVE = frozenset({BPOS, MPOS, SPOS})
NEGATIVE = frozenset({BNEG, MNEG, SNEG})

Primitive = list[float]  # [avg, max, min, start, finish, gradient, label]
"""A primitive record; like MATLAB's double matrices it holds the integer label as a number."""
BlockStats = tuple[
    int,
    list[float],
    list[float],
    list[list[float]],
    list[list[float]],
    list[list[float]],
    list[list[float]],
    list[list[float]],
    list[float],
    list[list[float]],
]
"""`block_stats`: (m, mean_t, Stt, mean_y, Syy, Sty, max_y, min_y, last_t, last_y) of K blocks."""


def ieee_div(a: float, b: float) -> float:
    """a / b with IEEE semantics (x/0 = +-inf, 0/0 = nan), as MATLAB divides."""
    if b != 0.0:
        return a / b
    if a == 0.0 or math.isnan(a):
        return math.nan
    return math.inf if (a > 0) == (math.copysign(1.0, b) > 0) else -math.inf


def running_sum(values: Iterable[float]) -> float:
    """Left-to-right float sum (MATLAB's order); builtin sum() compensates on Python >= 3.12."""
    total = 0.0
    for v in values:
        total += v
    return total


def fitted_average(vmax: float, vmin: float) -> float:
    """dAvg of statisticalData.m: (max+min)/2, written as the original does for mixed signs."""
    if (vmax >= 0 and vmin >= 0) or (vmax <= 0 and vmin <= 0):
        return (vmax + vmin) / 2
    return vmax - (abs(vmax) + abs(vmin)) / 2


# --------------------------------------------------------------------------- gradient labels


def axis_domain(values: np.ndarray, config: TaxonomyConfig) -> float:
    """|1.02 * 4th-largest| + |0.98 * 4th-smallest| sample of an axis (adjustAxes.m)."""
    n = len(values)
    if n == 0:
        return 0.0
    rank = min(config.domain_rank, n)
    part = np.partition(values, (rank - 1, n - rank))
    return abs(config.domain_top_margin * float(part[n - rank])) + abs(
        config.domain_bottom_margin * float(part[rank - 1])
    )


def axis_thresholds(axis: str, domain: float | None, config: TaxonomyConfig) -> tuple[float, ...]:
    """The 8-value spectrum [pimp bpos mpos spos sneg mneg bneg nimp] after the domain rule.

    A small domain divides the default spectrum by domain_divisor; a calibrated spectrum keeps
    its spos and is rebuilt from pimp / domain_divisor (GradientClassification.m, spec 2.1)."""
    values = config.thresholds(axis)
    if axis in config.domain_axes and domain is not None and domain < config.domain_threshold:
        if config.calibrated_thresholds and axis in config.calibrated_thresholds:
            return gradient_spectrum(values[0] / config.domain_divisor, values[3])
        values = tuple(v / config.domain_divisor for v in values)
    return values


def classify_gradient(g: float, thresholds: Sequence[float]) -> int:
    """Label integer of one gradient (GradientClassification.m); g == nimp exactly is 'none'."""
    pimp, bpos, mpos, spos, sneg, mneg, bneg, nimp = thresholds
    if g >= 0:
        return _rising_label(g, pimp, bpos, mpos, spos)
    return _falling_label(g, sneg, mneg, bneg, nimp)


def _rising_label(g: float, pimp: float, bpos: float, mpos: float, spos: float) -> int:
    """Label of a gradient g >= 0: pimp, bpos, mpos, spos from the steepest, else cons."""
    if g >= pimp:
        return PIMP
    if g >= bpos:
        return BPOS
    if g >= mpos:
        return MPOS
    if g >= spos:
        return SPOS
    return CONS


def _falling_label(g: float, sneg: float, mneg: float, bneg: float, nimp: float) -> int:
    """Label of a gradient that is not >= 0: nimp, bneg, mneg, sneg from the steepest, else
    cons; g == nimp exactly and nan are 'none', as in the original."""
    if g < nimp:
        return NIMP
    if g == nimp:
        return NONE
    if g <= bneg:
        return BNEG
    if g <= mneg:
        return MNEG
    if g <= sneg:
        return SNEG
    if g < 0:
        return CONS
    return NONE  # nan


# --------------------------------------------------------------------------- segmentation


def block_stats(t: np.ndarray, y: np.ndarray) -> BlockStats:
    """Least-squares statistics of K blocks of m samples: t (K, m), y (K, m, A) -> nested lists.

    Returns (m, mean_t, Stt, mean_y, Syy, Sty, max_y, min_y, last_t, last_y); the per-axis entries
    are axis-major (A, K) lists. Centred sums keep the precision of a direct polyfit. Every sum runs over the m
    samples in order with element-wise operations, so one block gives bit-identical numbers
    whether it is computed alone (streaming, `block_stats_one`) or among many (batch).
    """
    m = t.shape[1]
    st = t[:, 0]
    sy = y[:, 0, :]
    for j in range(1, m):
        st = st + t[:, j]
        sy = sy + y[:, j, :]
    mt = st / m
    my = sy / m
    dt = t[:, 0] - mt
    dy = y[:, 0, :] - my
    stt = dt * dt
    syy = dy * dy
    sty = dt[:, None] * dy
    ymax = y[:, 0, :]
    ymin = y[:, 0, :]
    for j in range(1, m):
        dt = t[:, j] - mt
        dy = y[:, j, :] - my
        stt = stt + dt * dt
        syy = syy + dy * dy
        sty = sty + dt[:, None] * dy
        ymax = np.maximum(ymax, y[:, j, :])
        ymin = np.minimum(ymin, y[:, j, :])
    return (
        m,
        mt.tolist(),
        stt.tolist(),
        my.T.tolist(),
        syy.T.tolist(),
        sty.T.tolist(),
        ymax.T.tolist(),
        ymin.T.tolist(),
        t[:, -1].tolist(),
        y[:, -1, :].T.tolist(),
    )


def block_stats_one(ts: list[float], ys: list[list[float]]) -> BlockStats:
    """`block_stats` of a single block in plain Python (same operations, same order, same bits).

    ts: the block's m times; ys: its m samples of A axes. Used per window step by the stream.
    """
    m = len(ts)
    if m == 5:  # the window step: the same sums, written out (left to right, same bits)
        return _block_stats_five(ts, ys)
    st = ts[0]
    for j in range(1, m):
        st = st + ts[j]
    mt = st / m
    dts = [x - mt for x in ts]
    stt = dts[0] * dts[0]
    for j in range(1, m):
        stt = stt + dts[j] * dts[j]
    d0 = dts[0]
    rest = dts[1:]
    my_col, syy_col, sty_col, max_col, min_col = [], [], [], [], []
    for col in zip(*ys, strict=True):
        sy = col[0]
        for v in col[1:]:
            sy = sy + v
        my = sy / m
        dy = col[0] - my
        syy = dy * dy
        sty = d0 * dy
        for dt, v in zip(rest, col[1:], strict=True):
            dy = v - my
            syy = syy + dy * dy
            sty = sty + dt * dy
        my_col.append([my])
        syy_col.append([syy])
        sty_col.append([sty])
        max_col.append([max(col)])
        min_col.append([min(col)])
    return (m, [mt], [stt], my_col, syy_col, sty_col, max_col, min_col, [ts[-1]],
            [[v] for v in ys[-1]])  # fmt: skip


def _block_stats_five(ts: list[float], ys: list[list[float]]) -> BlockStats:
    """block_stats_one for W = 5 samples, unrolled; Python adds left to right like the loops."""
    t0, t1, t2, t3, t4 = ts
    mt = (t0 + t1 + t2 + t3 + t4) / 5
    d0, d1, d2, d3, d4 = t0 - mt, t1 - mt, t2 - mt, t3 - mt, t4 - mt
    stt = d0 * d0 + d1 * d1 + d2 * d2 + d3 * d3 + d4 * d4
    my_col, syy_col, sty_col, max_col, min_col = [], [], [], [], []
    for y0, y1, y2, y3, y4 in zip(*ys, strict=True):
        my = (y0 + y1 + y2 + y3 + y4) / 5
        e0, e1, e2, e3, e4 = y0 - my, y1 - my, y2 - my, y3 - my, y4 - my
        my_col.append([my])
        syy_col.append([e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3 + e4 * e4])
        sty_col.append([d0 * e0 + d1 * e1 + d2 * e2 + d3 * e3 + d4 * e4])
        max_col.append([max(y0, y1, y2, y3, y4)])
        min_col.append([min(y0, y1, y2, y3, y4)])
    return (5, [mt], [stt], my_col, syy_col, sty_col, max_col, min_col, [t4],
            [[v] for v in ys[-1]])  # fmt: skip


def _fitted_segment(slope: float, wmt: float, wmy: float, ts: float, finish: float) -> list[float]:
    """The closed segment [avg, max, min, start, finish, gradient] of the line through the
    window mean (wmt, wmy) from ts to finish; a one-sample segment ends finish / 20 later."""
    f0 = wmy + slope * (ts - wmt)
    f1 = wmy + slope * (finish - wmt)
    if finish == ts:  # a one-sample segment (after the first window closed)
        finish = finish + finish / 20
    hi, lo = (f0, f1) if f0 >= f1 else (f1, f0)
    return [fitted_average(hi, lo), hi, lo, ts, finish, slope]


def _point_and_block(pt: float, py: float, stats: BlockStats, a: int, j: int) -> list[float]:
    """The open-segment state [n, mt, my, Stt, Syy, Sty, max, min, start] of the sample at
    (pt, py) merged with block j of axis a: a segment after the first restarts there."""
    m, bmt, bstt, bmy, bsyy, bsty, bmax, bmin, _blt, _bly = stats
    # S = point(i) (+) block j
    nn = 1.0 + m
    dt = bmt[j] - pt
    dy = bmy[a][j] - py
    f = m / nn
    amax, amin = bmax[a][j], bmin[a][j]
    return [
        nn,
        pt + dt * m / nn,
        py + dy * m / nn,
        bstt[j] + dt * dt * f,
        bsyy[a][j] + dy * dy * f,
        bsty[a][j] + dt * dy * f,
        amax if amax > py else py,
        amin if amin < py else py,
        pt,
    ]


class Segmenter:
    """Growing-window regression segmentation of A axes (fitRegressionCurves.m), fed block by block.

    State per axis: the open segment's running statistics (n, mean_t, mean_y, Stt, Syy, Sty, raw
    max/min) and its start time. Closed segments are appended to `segments[axis]` as
    [avg, max, min, start, finish, gradient] (labels are attached by the caller, because the
    moment-axis rule may need the whole trial).
    """

    def __init__(self, config: TaxonomyConfig, n_axes: int = len(AXES)) -> None:
        self.window = config.window
        self.threshold = config.fit_threshold
        self.zero = config.fit_zero_sum
        floors = config.fit_noise_floor or {}
        self.floors = [float(floors.get(axis, 0.0)) for axis in AXES[:n_axes]]
        """Per-axis residual variance per sample that counts as a fit (0: the R^2 test only)."""
        self.n_axes = n_axes
        self.samples = 0
        self.blocks = 0
        """Number of full W-sample blocks fed so far (the window-step index k)."""
        self.first_t = 0.0
        self.first_y: list[float] = [0.0] * n_axes
        self.last_t = 0.0
        self.last_y: list[float] = [0.0] * n_axes
        # open segment per axis: [n, mt, my, Stt, Syy, Sty, ymax, ymin, start_t]
        self.state: list[list[float]] = []
        self.segments: list[list[list[float]]] = [[] for _ in range(n_axes)]
        self.finished = False

    # The segment statistics start from the first sample; each later block (samples i+1..i+W of
    # the window step at i = 1 + W*k) is merged into them.
    def start(self, t0: float, y0: Sequence[float]) -> None:
        """Feed the very first sample."""
        self.samples = 1
        self.first_t = self.last_t = float(t0)
        self.first_y = [float(v) for v in y0]
        self.last_y = list(self.first_y)
        self.state = [
            [1.0, self.first_t, v, 0.0, 0.0, 0.0, v, v, self.first_t] for v in self.first_y
        ]

    def feed_blocks(self, stats: BlockStats, count: int, final: bool = False) -> list[int]:
        """Advance every axis over `count` blocks (block_stats output); returns axes that closed.

        With `final`, the last of the blocks is the partial last pass (possibly empty: count may
        include one block of n = 0 given as None stats) and the final segments are emitted.
        """
        m, _bmt, _bstt, _bmy, _bsyy, _bsty, _bmax, _bmin, blt, bly = stats
        n_full = count - 1 if final else count
        closed = [a for a in range(self.n_axes) if self._advance_axis(a, stats, n_full)]
        if n_full:
            self.blocks += n_full
            self.last_t = blt[n_full - 1]
            self.last_y = [col[n_full - 1] for col in bly]
        if final:
            self.finish(stats if count > n_full and m else None, count - 1)
        return closed

    def _advance_axis(self, a: int, stats: BlockStats, n_full: int) -> bool:
        """Grow axis a's open segment over the first `n_full` blocks while the line still fits,
        closing it and starting the next where it does not; True if a segment closed."""
        m, bmt, bstt, bmy, bsyy, bsty, bmax, bmin, blt, bly = stats
        threshold, zero, floor, k0 = self.threshold, self.zero, self.floors[a], self.blocks
        n, mt, my, stt, syy, sty, smax, smin, ts = self.state[a]
        pt, py = self.last_t, self.last_y[a]
        segs = self.segments[a]
        before = len(segs)
        amy, asyy, asty, amax, amin, aly = bmy[a], bsyy[a], bsty[a], bmax[a], bmin[a], bly[a]
        for j in range(n_full):
            # W = S (+) block j  (Chan et al. pairwise update)
            bt, by = bmt[j], amy[j]
            nn = n + m
            dt, dy = bt - mt, by - my
            f = n * m / nn
            wtt = stt + bstt[j] + dt * dt * f
            wyy = syy + asyy[j] + dy * dy * f
            wty = sty + asty[j] + dt * dy * f
            # R^2 = 1 - SSres/SStot with the original's zero clamps and nan/inf -> 1
            if wyy < zero:
                good = True
            else:
                ssres = wyy - wty * wty / wtt if wtt > 0 else wyy
                # floor 0: ssres <= 0 is already < zero, so the original test is unchanged
                good = ssres < zero or ssres <= nn * floor or 1.0 - ssres / wyy > threshold
            if good:
                n, stt, syy, sty = nn, wtt, wyy, wty
                mt = mt + dt * m / nn
                my = my + dy * m / nn
                v = amax[j]
                if v > smax:
                    smax = v
                v = amin[j]
                if v < smin:
                    smin = v
            else:
                slope = wty / wtt if wtt > 0 else 0.0
                lt, ly = blt[j], aly[j]
                # the first window of the signal keeps all of it; later ones end at i
                first = k0 + j == 0
                wmt, wmy = mt + dt * m / nn, my + dy * m / nn
                segs.append(_fitted_segment(slope, wmt, wmy, ts, lt if first else pt))
                if first:
                    n, mt, my, stt, syy, sty, smax, smin, ts = (
                        1.0,
                        lt,
                        ly,
                        0.0,
                        0.0,
                        0.0,
                        ly,
                        ly,
                        lt,
                    )
                else:
                    n, mt, my, stt, syy, sty, smax, smin, ts = _point_and_block(pt, py, stats, a, j)
            pt, py = blt[j], aly[j]
        self.state[a] = [n, mt, my, stt, syy, sty, smax, smin, ts]
        return len(segs) != before

    def finish(self, stats: tuple[Any, ...] | None = None, j: int = 0) -> None:
        """The last pass (with block j of `stats`, the partial last window, if any): wStart..N
        fitted once; raw max/min; never split (spec 2.1 step 2). Public: the stream ends with it."""
        self.finished = True
        if self.samples < 2:
            return
        for a in range(self.n_axes):
            n, mt, my, stt, _syy, sty, smax, smin, ts = self.state[a]
            end = self.last_t
            if stats is not None:
                m, bmt, bstt, bmy, _bsyy, bsty, bmax, bmin, blt, _bly = stats
                nn = n + m
                dt = bmt[j] - mt
                dy = bmy[a][j] - my
                f = n * m / nn
                stt = stt + bstt[j] + dt * dt * f
                sty = sty + bsty[a][j] + dt * dy * f
                smax = max(smax, bmax[a][j])
                smin = min(smin, bmin[a][j])
                end = blt[j]
            slope = sty / stt if stt > 0 else 0.0
            finish = end if end != ts else end + end / 20
            self.segments[a].append([fitted_average(smax, smin), smax, smin, ts, finish, slope])


def segment_arrays(time: np.ndarray, wrench: np.ndarray, config: TaxonomyConfig) -> Segmenter:
    """Segment a whole (N,) time / (N, A) signal: the batch use of the incremental Segmenter."""
    n = len(time)
    seg = Segmenter(config, wrench.shape[1] if wrench.ndim == 2 else len(AXES))
    if n == 0:
        seg.finished = True
        return seg
    w = config.window
    seg.start(time[0], wrench[0])
    seg.samples = n
    full = (n - 1) // w
    rest = (n - 1) - full * w
    if full:
        stats = block_stats(
            time[1 : 1 + full * w].reshape(full, w), wrench[1 : 1 + full * w].reshape(full, w, -1)
        )
        seg.feed_blocks(stats, full)
    if rest:
        stats = block_stats(
            time[1 + full * w :].reshape(1, rest), wrench[1 + full * w :].reshape(1, rest, -1)
        )
        seg.feed_blocks(stats, 1, final=True)
    else:
        seg.finish()
    return seg


# --------------------------------------------------------------------------- clean-up


def merge_pair(p1: Primitive, p2: Primitive, keep_second: bool) -> Primitive:
    """MergePrimitives for a duration-context pair: label of the longer one, means, max/min."""
    return [
        (p1[AVG] + p2[AVG]) / 2, max(p1[MAX], p2[MAX]), min(p1[MIN], p2[MIN]),
        p1[START], p2[FINISH], (p1[GRAD] + p2[GRAD]) / 2, p2[LABEL] if keep_second else p1[LABEL],
    ]  # fmt: skip


def duration_pair(p1: Primitive, p2: Primitive, config: TaxonomyConfig) -> Primitive | None:
    """Clean-up step 2 for one pair: the merged primitive, or None when the pair is kept."""
    if p1[LABEL] in (PIMP, NIMP):
        return None
    amp_ratio = ieee_div(abs(p2[MAX] - p2[MIN]), abs(p1[MAX] - p1[MIN]))
    limit = config.primitive_amplitude_ratio
    if amp_ratio == 0 or amp_ratio == math.inf or amp_ratio > limit or amp_ratio < 1 / limit:
        return None
    ratio = ieee_div(p1[FINISH] - p1[START], p2[FINISH] - p2[START])
    if ratio == 0 or ratio == math.inf:
        return None
    length = config.primitive_length_ratio
    if ratio > length:
        return merge_pair(p1, p2, keep_second=False)
    if ratio < 1 / length:
        return merge_pair(p1, p2, keep_second=True)
    return None


# --------------------------------------------------------------------------- calibration


def calibrate_limits(
    prims: list[Primitive], state_times: Sequence[float], axis: str
) -> tuple[float, float]:
    """(pimp, pConst) of one axis from a successful trial's primitives (ROBIO'12 optimisation)."""
    s2, s3, s4 = state_times[1], state_times[2], state_times[3]
    pconst = 0.0
    if axis in ("Fx", "My"):
        rot = []
        for p in prims:
            if p[FINISH] > s3:
                break
            if p[START] > s2:
                rot.append(p[GRAD])
        if rot:
            pconst = 0.9 * abs(running_sum(rot) / len(rot))
    ins = [abs(p[GRAD]) for p in prims if p[START] > s3 and p[FINISH] < s4]
    pimp = 0.85 * max(ins) if ins else 0.0
    return pimp, pconst


def gradient_spectrum(pimp: float, pconst: float) -> tuple[float, ...]:
    """computeGradientSpectrum: [pimp bpos mpos spos sneg mneg bneg nimp] from (pimp, pConst)."""
    delta = (pimp - pconst) / 3
    pos = (pimp, pimp - delta, pimp - 2 * delta, pconst)
    return (*pos, -pos[3], -pos[2], -pos[1], -pos[0])


def primitive_word(p: Primitive, axis: str, arm: str, seq: int = 0) -> Word:
    """A primitive record as a Word with the Segments keys."""
    return Word(
        axis=axis, level=Level.PRIMITIVE, label=PRIMITIVE_LABELS[int(p[6]) - 1],
        start=p[3], end=p[4], arm=arm, seq=seq,
        features={"Average": p[0], "Max Val": p[1], "Min Val": p[2], "Start": p[3],
                  "Finish": p[4], "Gradient": p[5]},
    )  # fmt: skip

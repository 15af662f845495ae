"""The MC layer's operators: the composition scan and cleanUp.m's seven filter steps (spec 2.2-2.3).

The rules (rule table, similarity, MergeCompositions, the sub-task limit) are in compositions.py;
these passes apply them in the original order. One cleanUp call's steps share a `CycleState`
(its startIndex and step 3's largest amplitude).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from rcbht_introspection.taxonomy import compositions as mc
from rcbht_introspection.taxonomy import primitives as pr
from rcbht_introspection.taxonomy.config import TaxonomyConfig
from rcbht_introspection.taxonomy.ops import (
    HoldsOneRow,
    Op,
    PairPass,
    Row,
    StreamContext,
    label_in,
    run_ops,
)


class Compose(HoldsOneRow):
    """The MC layer: P1 with the next primitive (the last one pairs with itself)."""

    end = pr.FINISH

    def __init__(self, config: TaxonomyConfig) -> None:
        self.config = config
        self.pending: Row | None = None

    def push(self, row: Row) -> list[Row]:
        if self.pending is None:
            self.pending = row
            return []
        out, paired = mc.match_primitives(self.pending, row, self.config)
        self.pending = None if paired else row
        return [out]

    def finish(self) -> list[Row]:
        if self.pending is None:
            return []
        out, _ = mc.match_primitives(self.pending, self.pending, self.config)
        self.pending = None
        return [out]


@dataclass
class CycleState:
    """Per cleanUp call: its startIndex and the largest amplitude found by step 3."""

    start: int | None = None
    start_known: bool = False
    seen: int = 0
    max_amp: float = 0.0
    max_amp_final: bool = False

    def before_start(self, pos: int) -> bool:
        """Is input position `pos` before startIndex? (Unknown start: it lies past every row
        step 1 has seen, and every later step's position p was produced from step-1 row >= p.)"""
        if self.start_known:
            return self.start is None or pos < self.start
        return True


class AdjustmentChains(Op):
    """Step 1: chains of similar 'a' (lookahead 3 rows; the time limit may need to be known)."""

    def __init__(self, ctx: StreamContext, cycle: CycleState) -> None:
        self.ctx, self.cycle = ctx, cycle
        self.rows: list[Row | None] = []  # buffered rows from position `base`
        self.base = 0
        self.next_i = 0  # next decision position
        self.ctr = 0
        self.repeat = False
        self.ended = False

    def _row(self, pos: int) -> Row | None:
        """The buffered row at input position `pos` (None once merged into an earlier row)."""
        return self.rows[pos - self.base]

    def _live(self, pos: int) -> Row:
        """The buffered row at `pos`, which the original's loop reads as unmerged."""
        row = self.rows[pos - self.base]
        assert row is not None, f"row {pos} was merged away"
        return row

    def _available(self) -> int:
        """The input position after the last buffered row."""
        return self.base + len(self.rows)

    def push(self, row: Row) -> list[Row]:
        pos = self._available()
        self.rows.append(row)
        cyc = self.cycle
        cyc.seen = pos + 1
        if not cyc.start_known:
            s2 = self.ctx.s2
            if s2 is not None and row[mc.T2E] > s2:
                cyc.start, cyc.start_known = pos, True
                self.next_i = pos
        return self._run()

    def poll(self) -> list[Row]:
        return self._run()

    def _decidable(self, i: int) -> bool:
        """Can the decision at position i be made with the rows (and time) known now?

        It reads row i+1 (the guard and the labels); only for an 'a','a' pair that keeps a
        chain going does it also read rows i+2 and i+3 (the chain-end check).
        """
        n = self._available()
        if self.ended:
            return i < n - 1
        if i + 1 >= n:
            return False
        r = self._row(i)
        if r is None:
            return True
        m = self._live(i + 1)
        cfg = self.ctx.config
        if cfg.adjustment_mating_guard:
            limit = self.ctx.limit()
            # an unknown limit is >= now - 0.002: the guard is true for MCs ending before that
            if limit is None and not self.ctx.causal and not m[mc.T2E] < self.ctx.now - 0.002:
                self.ctx.waiting.add(self)
                return False
            self.ctx.waiting.discard(self)
            if limit is not None and not m[mc.T2E] < limit:
                return True
        if r[mc.LBL] != mc.A or m[mc.LBL] != mc.A:
            return True
        keeps_chain = self.repeat or mc.similar(r[mc.AVGV], m[mc.AVGV], cfg.adjustment_similarity)
        return not keeps_chain or i + 3 < n

    def _decide(self, i: int) -> None:
        """The step at position i (the original's loop body): count, extend or merge a chain."""
        cfg = self.ctx.config
        n = self._available() if self.ended else math.inf
        r = self._row(i)
        if r is None:
            return
        m = self._live(i + 1)
        if cfg.adjustment_mating_guard:
            limit = self.ctx.limit()
            if limit is None:
                limit = math.inf  # causal, or known to lie past this MC
            if not m[mc.T2E] < limit:
                return
        w = cfg.adjustment_similarity
        if r[mc.LBL] == mc.A and m[mc.LBL] == mc.A:
            if mc.similar(r[mc.AVGV], m[mc.AVGV], w):
                self.repeat = True
                self.ctr += 1
            j = i + 1
            if self.repeat and self.ctr > 0 and j + 1 < n - 1:
                nxt, nxt2 = self._live(j + 1), self._live(j + 2)
                if nxt[mc.LBL] != mc.A or not mc.similar(nxt[mc.AVGV], nxt2[mc.AVGV], w):
                    self._merge(i - (self.ctr - 1), self.ctr)

    def _merge(self, fi: int, ctr: int) -> None:
        """Merge the chain of rows fi..fi+ctr into row fi and drop the others."""
        cfg = self.ctx.config
        li = fi + ctr
        run = [self._live(x) for x in range(fi, li + 1)]
        mc.merge_adjustment_chain(run, cfg.adjustment_time_offset, cfg.adjustment_time_step)
        for x in range(fi + 1, li + 1):
            self.rows[x - self.base] = None
        self.repeat = False
        self.ctr = 0

    def _run(self) -> list[Row]:
        """Decide every position that can be decided now and release the rows before them."""
        cyc = self.cycle
        if cyc.start_known and cyc.start is not None:
            while self.next_i < self._available() and self._decidable(self.next_i):
                self._decide(self.next_i)
                self.next_i += 1
            safe = self.next_i - self.ctr
        else:  # startIndex known or not yet reached, or the stream ended: all buffered rows
            safe = self._available()
        out: list[Row] = []
        while self.base < safe and self.rows:
            row = self.rows.pop(0)
            self.base += 1
            if row is not None:
                out.append(row)
        return out

    def oldest_end(self) -> float:
        return next((r[mc.T2E] for r in self.rows if r is not None), math.inf)

    def finish(self) -> list[Row]:
        self.ended = True
        self.ctx.waiting.discard(self)
        if not self.cycle.start_known:
            self.cycle.start_known = True  # no MC ends after the rotation start: steps skipped
        out = self._run()
        out += [r for r in self.rows if r is not None]
        self.base += len(self.rows)
        self.rows = []
        return out

    def retained(self) -> int:
        return len(self.rows)


class RepeatedCompositions(Op):
    """Step 2: runs of identical non-'a' labels merge into their first MC (MergeCompositions)."""

    def __init__(self) -> None:
        self.first: Row | None = None
        self.last: Row | None = None
        self.count = 0
        self.sum_avg = 0.0
        self.max_rms = -math.inf

    def _flush(self) -> list[Row]:
        """Merge the held run (if longer than one row) and release it."""
        if self.first is None:
            return []
        r, last, k = self.first, self.last, self.count
        assert last is not None
        if k >= 2:
            mc.merge_compositions(r, last, k, self.sum_avg, self.max_rms, None, None)
        self.first = self.last = None
        return [r]

    def push(self, row: Row) -> list[Row]:
        if self.first is not None and row[mc.LBL] == self.first[mc.LBL]:
            self.last = row
            self.count += 1
            self.sum_avg += row[mc.AVGV]
            self.max_rms = max(self.max_rms, row[mc.RMS])
            return []
        out = self._flush()
        if row[mc.LBL] == mc.A:
            return [*out, row]
        self.first = self.last = row
        self.count = 1
        self.sum_avg = 0.0 + row[mc.AVGV]
        self.max_rms = row[mc.RMS]
        return out

    def finish(self) -> list[Row]:
        return self._flush()

    def oldest_end(self) -> float:
        return math.inf if self.last is None else self.last[mc.T2E]

    def retained(self) -> int:
        return 1 if self.first is not None else 0


class PrimitiveDurations(HoldsOneRow):
    """Step 3: relabel from the much longer primitive; stops at the first amplitude-gate failure."""

    end = mc.T2E

    def __init__(self, ctx: StreamContext, cycle: CycleState) -> None:
        self.ctx, self.cycle = ctx, cycle
        self.pending: Row | None = None
        self.pos = 0
        self.stopped = False

    def _decide(self, r: Row, nxt: Row) -> None:
        """Step 3 on row `r` given the next row: relabel it, track the largest amplitude."""
        cfg = self.ctx.config
        if r[mc.LBL] in mc.CONTACTS:
            return
        amp_ratio = pr.ieee_div(abs(nxt[mc.AMP]), abs(r[mc.AMP]))
        if amp_ratio == 0 or amp_ratio == math.inf:
            return
        lim = cfg.duration_amplitude_ratio
        if amp_ratio > lim or amp_ratio < 1 / lim:
            if cfg.duration_gate_breaks:
                self.stopped = True
                self.cycle.max_amp_final = True
            return
        p1 = r[mc.T1E] - r[mc.T1S]
        p2 = r[mc.T2E] - r[mc.T2S]
        if p1 == 0 or p2 == 0:
            return
        ratio = p1 / p2
        glabel = r[mc.GL1] if ratio > cfg.duration_ratio else (
            r[mc.GL2] if ratio < 1 / cfg.duration_ratio else None)  # fmt: skip
        if glabel is not None:
            new = mc.relabel_from(glabel)
            if new is not None:
                r[mc.LBL] = new
        if r[mc.AMP] > self.cycle.max_amp:
            self.cycle.max_amp = r[mc.AMP]

    def resume(self, previous: Op) -> None:
        assert isinstance(previous, PrimitiveDurations)
        self.stopped = previous.stopped
        self.cycle.max_amp = previous.cycle.max_amp
        self.cycle.max_amp_final = previous.cycle.max_amp_final and previous.stopped

    def push(self, row: Row) -> list[Row]:
        pos = self.pos
        self.pos += 1
        if self.stopped:
            return [row]
        out: list[Row] = []
        if self.pending is not None:
            self._decide(self.pending, row)
            out.append(self.pending)
            self.pending = None
        if self.stopped or self.cycle.before_start(pos) or row[mc.LBL] in mc.CONTACTS:
            out.append(row)  # contacts are skipped: nothing about them waits for the next MC
        else:
            self.pending = row
        return out

    def finish(self) -> list[Row]:
        self.cycle.max_amp_final = True
        return super().finish()


class CompositionDurations(HoldsOneRow):
    """Step 4: absorb an MC into a neighbour five times longer; stops like step 3."""

    end = mc.T2E

    def __init__(self, ctx: StreamContext, cycle: CycleState) -> None:
        self.ctx, self.cycle = ctx, cycle
        self.pending: Row | None = None
        self.pos = 0
        self.stopped = False

    def resume(self, previous: Op) -> None:
        assert isinstance(previous, CompositionDurations)
        self.stopped = previous.stopped

    def _advance(self, row: Row, out: list[Row]) -> list[Row]:
        """`row` is the next to be examined: contacts are skipped, so they need not wait."""
        if row[mc.LBL] in mc.CONTACTS:
            out.append(row)
        else:
            self.pending = row
        return out

    def push(self, row: Row) -> list[Row]:
        pos = self.pos
        self.pos += 1
        if self.stopped:
            return [row]
        if self.pending is None:
            if self.cycle.before_start(pos):
                return [row]
            return self._advance(row, [])
        r = self.pending
        self.pending = None
        cfg = self.ctx.config
        lbl = r[mc.LBL]
        amp_ratio = pr.ieee_div(abs(row[mc.AMP]), abs(r[mc.AMP]))
        if amp_ratio == 0 or amp_ratio == math.inf:
            return self._advance(row, [r])
        lim = cfg.duration_amplitude_ratio
        if amp_ratio > lim or amp_ratio < 1 / lim:
            if cfg.duration_gate_breaks:
                self.stopped = True
                return [r, row]
            return self._advance(row, [r])
        c1 = r[mc.T2E] - r[mc.T1S]
        c2 = row[mc.T2E] - row[mc.T1S]
        if c1 == 0 or c2 == 0:
            return self._advance(row, [r])
        ratio = c1 / c2
        if ratio > cfg.duration_ratio:
            mc.merge_next(r, row, lbl if lbl in (mc.A, mc.I, mc.D, mc.K) else None, False)
            # the emptied row's turn never changes anything; the next pair starts after it
            return [r]
        if ratio < 1 / cfg.duration_ratio:
            mc.merge_previous(row, r, None, False)
            return self._advance(row, [])  # the merged row is compared with the next one
        return self._advance(row, [r])


class ContactAmplitudes(Op):
    """Step 5: pc/nc below 10 % of step 3's largest amplitude become i/d.

    The largest amplitude only grows until step 3 stops, so a contact already below the limit is
    final; one above it waits (with every later row, to keep the order) unless causal.
    """

    def __init__(self, ctx: StreamContext, cycle: CycleState) -> None:
        self.ctx, self.cycle = ctx, cycle
        self.held: list[Row] = []

    def _apply(self, r: Row) -> bool:
        """Relabel if due; False if the row must wait for the final largest amplitude."""
        if r[mc.LBL] not in (mc.PC, mc.NC):
            return True
        limit = self.ctx.config.contact_amplitude_fraction * abs(self.cycle.max_amp)
        if abs(r[mc.AMP]) < limit:
            r[mc.LBL] = mc.I if r[mc.LBL] == mc.PC else mc.D
            return True
        return self.cycle.max_amp_final or self.ctx.causal

    def _drain(self) -> list[Row]:
        """Release held rows, in order, up to the first that must wait."""
        out: list[Row] = []
        while self.held and self._apply(self.held[0]):
            out.append(self.held.pop(0))
        return out

    def push(self, row: Row) -> list[Row]:
        self.held.append(row)
        return self._drain()

    def poll(self) -> list[Row]:
        return self._drain()

    def oldest_end(self) -> float:
        return self.held[0][mc.T2E] if self.held else math.inf

    def finish(self) -> list[Row]:
        self.cycle.max_amp_final = True
        return self._drain()

    def retained(self) -> int:
        return len(self.held)


def similar_pairs(
    pairs: frozenset[tuple[int, int]], widths: tuple[float, float], label: int
) -> Callable[[Row, Row], Row | None]:
    """Steps 6/7 decision: listed label pairs with similar amplitude and avgVal merge as `label`."""
    wa, wm = widths

    def decide(r: Row, m: Row) -> Row | None:
        """Merge `m` into `r` and return `r` when the pair qualifies, else None."""
        if (
            (r[mc.LBL], m[mc.LBL]) in pairs
            and mc.similar(r[mc.AMP], m[mc.AMP], wa)
            and mc.similar(r[mc.AVGV], m[mc.AVGV], wm)
        ):
            mc.merge_next(r, m, label, True)
            return r
        return None

    return decide


def composition_cycle(ctx: StreamContext) -> list[Op]:
    """One cleanUp.m call as seven operators sharing its startIndex and largest amplitude."""
    cfg = ctx.config
    cycle = CycleState()
    adjust = similar_pairs(mc.ADJUST_PAIRS, cfg.adjustment_merge_similarity, mc.A)
    constant = similar_pairs(mc.CONSTANT_PAIRS, cfg.constant_merge_similarity, mc.K)
    return [
        AdjustmentChains(ctx, cycle),
        RepeatedCompositions(),
        PrimitiveDurations(ctx, cycle),
        CompositionDurations(ctx, cycle),
        ContactAmplitudes(ctx, cycle),
        PairPass(adjust, cycle.before_start, label_in(mc.A, mc.I, mc.D, field=mc.LBL), mc.T2E),
        PairPass(constant, cycle.before_start, label_in(mc.I, mc.K, mc.D, field=mc.LBL), mc.T2E),
    ]


def compose(prims: list[Row], config: TaxonomyConfig) -> list[Row]:
    """CompoundMotionComposition's scan on a whole axis (before filtering)."""
    return run_ops([Compose(config)], prims)

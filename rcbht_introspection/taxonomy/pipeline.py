"""The RCBHT upper layers as a chain of resumable left-to-right operators.

Each pass of the original code (primitive clean-up, MC layer, the seven MC filter steps run four
times, LLB layer, the six refinement steps run five times) is one operator with `push(row)` and
`finish()`. An operator returns a row only once no later input can change it, so the chain emits
exactly the rows that are final. The batch engine pushes a whole axis and calls finish(); the
streaming engine pushes rows as segments close. Both therefore run the same code, and the rows
come out identical to the original whole-sequence passes (see the rule functions in
primitives.py, compositions.py and behaviors.py, which the operators call).

Whole-trial inputs of the reference algorithm reach the operators through `StreamContext`:
the sub-task start times (rotation start s2 -> startIndex; mating start -> the 'a'-chain time
limit), the time of the latest sample (a boundary is never marked later than the samples it
precedes, so unknown boundaries lie in the future) and, per MC cycle, the largest amplitude of
step 3 (final once that pass stops).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from rcbht_introspection.taxonomy import behaviors as bh
from rcbht_introspection.taxonomy import compositions as mc
from rcbht_introspection.taxonomy import primitives as pr
from rcbht_introspection.taxonomy.config import TaxonomyConfig

Row = list


@dataclass
class StreamContext:
    """What the operators may know about the trial beyond their own rows."""

    config: TaxonomyConfig
    causal: bool = False
    """Decide with what is known now instead of waiting for whole-trial quantities."""
    boundaries: list[float] = field(default_factory=list)
    """Marked sub-task start times in order (approach, rotation, insertion, mating)."""
    now: float = -math.inf
    """Time of the latest sample; unmarked boundaries are not earlier than this."""
    ended: bool = False
    end_time: float = 0.0
    _limit_key: tuple = ()
    _limit: float | None = None
    waiting: set = field(default_factory=set)
    """Operators waiting for time to pass (the 'a'-chain limit); poll them as samples arrive."""

    @property
    def s2(self) -> float | None:
        return self.boundaries[1] if len(self.boundaries) > 1 else None

    def limit(self) -> float | None:
        """The 'a'-chain time limit (cleanUp stateVec(2,2)) if it is already determined."""
        key = (len(self.boundaries), self.ended, self.end_time)
        if key != self._limit_key:
            known = len(self.boundaries) >= 4 or self.ended
            self._limit = mc.state_limits(self.boundaries, self.end_time)[1] if known else None
            self._limit_key = key
        return self._limit


class Op:
    """One resumable pass: push final input rows, receive final output rows."""

    def push(self, row: Row) -> list[Row]:
        raise NotImplementedError

    def finish(self) -> list[Row]:
        return []

    def retained(self) -> int:
        """Rows held back (for the bounded-memory check)."""
        return 0

    def poll(self) -> list[Row]:
        """Rows that became final without new input (e.g. when time advanced)."""
        return []


class BufferedOp(Op):
    """A pass that buffers rows and decides in `_step(ended)` how many it can release."""

    rows: list[Row]

    def _step(self, ended: bool) -> list[Row]:
        raise NotImplementedError

    def push(self, row: Row) -> list[Row]:
        self.rows.append(row)
        return self._step(False)

    def finish(self) -> list[Row]:
        return self._step(True)

    def retained(self) -> int:
        return len(self.rows)


# --------------------------------------------------------------------------- primitive clean-up


class RepeatedPrimitives(Op):
    """Clean-up step 1: a run of equal labels is merged when a different label follows."""

    def __init__(self) -> None:
        self.first: Row | None = None
        self.last: Row | None = None
        self.count = 0
        self.sum_avg = 0.0
        self.sum_grad = 0.0
        self.vmax = -math.inf
        self.vmin = math.inf

    def _flush(self) -> list[Row]:
        if self.first is None:
            return []
        first, last, k = self.first, self.last, self.count
        assert last is not None
        if k == 1:
            out = first
        else:
            div = 2 if k == 2 else k - 1  # [bug] k >= 3 rows divide by k - 1
            out = [
                self.sum_avg / div, self.vmax, self.vmin, first[pr.START], last[pr.FINISH],
                self.sum_grad / div, last[pr.LABEL] if k == 2 else first[pr.LABEL],
            ]  # fmt: skip
        self.first = self.last = None
        return [out]

    def push(self, row: Row) -> list[Row]:
        out: list[Row] = []
        if self.first is not None and row[pr.LABEL] != self.first[pr.LABEL]:
            out = self._flush()
        if self.first is None:
            self.first, self.count = row, 0
            self.sum_avg = self.sum_grad = 0.0
            self.vmax, self.vmin = -math.inf, math.inf
        self.last = row
        self.count += 1
        self.sum_avg += row[pr.AVG]
        self.sum_grad += row[pr.GRAD]
        if row[pr.MAX] > self.vmax:
            self.vmax = row[pr.MAX]
        if row[pr.MIN] < self.vmin:
            self.vmin = row[pr.MIN]
        return out

    def finish(self) -> list[Row]:
        return self._flush()

    def retained(self) -> int:
        return 1 if self.first is not None else 0


class PairPass(Op):
    """A greedy left-to-right pass over pairs (i, i+1); a merged pair is not compared again.

    `decide(a, b)` returns the merged row or None. Rows before `start(pos)` pass through, and so
    does a row that `can_start` says can never be the first of a merging pair (it waits for no
    one: the previous pair was already decided without it).
    """

    def __init__(
        self,
        decide: Callable[[Row, Row], Row | None],
        start: Callable[[int], bool] | None = None,
        can_start: Callable[[Row], bool] | None = None,
    ) -> None:
        self.decide = decide
        self.before_start = start
        self.can_start = can_start
        self.pending: Row | None = None
        self.pos = 0  # position of the next input row

    def push(self, row: Row) -> list[Row]:
        pos = self.pos
        self.pos += 1
        out: list[Row] = []
        if self.pending is not None:
            first = self.pending
            self.pending = None
            merged = self.decide(first, row)
            if merged is not None:
                return [merged]
            out.append(first)
        if (self.before_start is None or not self.before_start(pos)) and (
            self.can_start is None or self.can_start(row)
        ):
            self.pending = row
        else:
            out.append(row)
        return out

    def finish(self) -> list[Row]:
        out = [self.pending] if self.pending is not None else []
        self.pending = None
        return out

    def retained(self) -> int:
        return 1 if self.pending is not None else 0


class Compose(Op):
    """The MC layer: P1 with the next primitive (the last one pairs with itself)."""

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

    def retained(self) -> int:
        return 1 if self.pending is not None else 0


# --------------------------------------------------------------------------- MC filtering


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
        return self.rows[pos - self.base]

    def _available(self) -> int:
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
        r, m = self._row(i), self._row(i + 1)
        if r is None:
            return True
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
        cfg = self.ctx.config
        n = self._available() if self.ended else math.inf
        r, m = self._row(i), self._row(i + 1)
        if r is None:
            return
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
                nxt, nxt2 = self._row(j + 1), self._row(j + 2)
                if nxt[mc.LBL] != mc.A or not mc.similar(nxt[mc.AVGV], nxt2[mc.AVGV], w):
                    self._merge(i - (self.ctr - 1), self.ctr)

    def _merge(self, fi: int, ctr: int) -> None:
        """Merge the chain of rows fi..fi+ctr into row fi and drop the others."""
        cfg = self.ctx.config
        li = fi + ctr
        run = [self._row(x) for x in range(fi, li + 1)]
        mc.merge_adjustment_chain(run, cfg.adjustment_time_offset, cfg.adjustment_time_step)
        for x in range(fi + 1, li + 1):
            self.rows[x - self.base] = None
        self.repeat = False
        self.ctr = 0

    def _run(self) -> list[Row]:
        cyc = self.cycle
        if cyc.start_known and cyc.start is not None:
            while self.next_i < self._available() and self._decidable(self.next_i):
                self._decide(self.next_i)
                self.next_i += 1
            safe = self.next_i - self.ctr
        elif cyc.start_known or not self.ended:
            safe = self._available()  # every buffered row lies before startIndex
        else:
            safe = self._available()
        out: list[Row] = []
        while self.base < safe and self.rows:
            row = self.rows.pop(0)
            self.base += 1
            if row is not None:
                out.append(row)
        return out

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
        self.second_avg = 0.0

    def _flush(self) -> list[Row]:
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

    def retained(self) -> int:
        return 1 if self.first is not None else 0


class PrimitiveDurations(Op):
    """Step 3: relabel from the much longer primitive; stops at the first amplitude-gate failure."""

    def __init__(self, ctx: StreamContext, cycle: CycleState) -> None:
        self.ctx, self.cycle = ctx, cycle
        self.pending: Row | None = None
        self.pos = 0
        self.stopped = False

    def _decide(self, r: Row, nxt: Row) -> None:
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
        out = [self.pending] if self.pending is not None else []
        self.pending = None
        return out

    def retained(self) -> int:
        return 1 if self.pending is not None else 0


class CompositionDurations(Op):
    """Step 4: absorb an MC into a neighbour five times longer; stops like step 3."""

    def __init__(self, ctx: StreamContext, cycle: CycleState) -> None:
        self.ctx, self.cycle = ctx, cycle
        self.pending: Row | None = None
        self.pos = 0
        self.stopped = False

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

    def finish(self) -> list[Row]:
        out = [self.pending] if self.pending is not None else []
        self.pending = None
        return out

    def retained(self) -> int:
        return 1 if self.pending is not None else 0


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
        out: list[Row] = []
        while self.held and self._apply(self.held[0]):
            out.append(self.held.pop(0))
        return out

    def push(self, row: Row) -> list[Row]:
        self.held.append(row)
        return self._drain()

    def poll(self) -> list[Row]:
        return self._drain()

    def finish(self) -> list[Row]:
        self.cycle.max_amp_final = True
        return self._drain()

    def retained(self) -> int:
        return len(self.held)


def similar_pairs(pairs: frozenset, widths: tuple[float, float], label: int) -> Callable:
    """Steps 6/7 decision: listed label pairs with similar amplitude and avgVal merge as `label`."""
    wa, wm = widths

    def decide(r: Row, m: Row) -> Row | None:
        if (
            (r[mc.LBL], m[mc.LBL]) in pairs
            and mc.similar(r[mc.AMP], m[mc.AMP], wa)
            and mc.similar(r[mc.AVGV], m[mc.AVGV], wm)
        ):
            mc.merge_next(r, m, label, True)
            return r
        return None

    return decide


# --------------------------------------------------------------------------- LLB layer


class ComposeBehaviors(BufferedOp):
    """llbehComposition: the time flag is set once and never reset; 'a' may look two MCs ahead."""

    def __init__(self, config: TaxonomyConfig) -> None:
        self.config = config
        self.rows: list[Row] = []
        self.flag = False

    def _step(self, ended: bool) -> list[Row]:
        out: list[Row] = []
        thresh = self.config.behavior_time_threshold
        while self.rows:
            m = self.rows[0]
            lbl = m[mc.LBL]
            need = 3 if lbl == mc.A else 2
            if not ended and len(self.rows) < need:
                break
            if lbl in (mc.K, mc.I, mc.D, mc.A) and m[mc.T2E] - m[mc.T1S] >= thresh:
                self.flag = True
            window = 1 if lbl == mc.A else 0
            view = self.rows[:need]
            record, nxt = bh.match_compositions(view, 0, self.flag, window)
            out.append(record)
            del self.rows[:nxt]
        return out


class BehaviorDurations(BufferedOp):
    """Refinement step 1: a prefix pass that stops at the first pair that does not merge."""

    def __init__(self, config: TaxonomyConfig) -> None:
        self.config = config
        self.rows: list[Row] = []  # rows from the next decision position
        self.skip = 0  # rows to pass through before the next decision (the jump of 3)
        self.stopped = False

    def _step(self, ended: bool) -> list[Row]:
        out: list[Row] = []
        cfg = self.config
        while self.rows:
            if self.stopped:
                out.extend(self.rows)
                self.rows = []
                break
            if self.skip:
                out.append(self.rows.pop(0))
                self.skip -= 1
                continue
            if len(self.rows) < 3:  # the pair (i, i+1) is examined only while i < n - 2
                if ended:
                    self.stopped = True
                    continue
                break
            r, m = self.rows[0], self.rows[1]
            if (
                r[bh.B_LBL] != bh.CT
                and m[bh.B_LBL] != bh.CT
                and r[bh.B_MC2] not in (mc.U, mc.Z)
                and m[bh.B_MC2] not in (mc.U, mc.Z)
            ):
                ratio = pr.ieee_div(abs(m[bh.B_AMP]), abs(r[bh.B_AMP]))
                if ratio == 0 or ratio == math.inf or ratio > cfg.behavior_amplitude_ratio:
                    self.stopped = True
                    continue
                if r[bh.B_MC2] != 6 and m[bh.B_MC2] != 6:
                    p1, p2 = r[bh.B_T2E] - r[bh.B_T1S], m[bh.B_T2E] - m[bh.B_T1S]
                elif r[bh.B_MC2] == 6:
                    p1, p2 = r[bh.B_T1E] - r[bh.B_T1S], m[bh.B_T2E] - m[bh.B_T1S]
                else:
                    p1, p2 = r[bh.B_T2E] - r[bh.B_T1S], m[bh.B_T1E] - m[bh.B_T1S]
                d = pr.ieee_div(p1, p2)
                if d > cfg.behavior_duration_ratio or d < 1 / cfg.behavior_duration_ratio:
                    if d > cfg.behavior_duration_ratio:
                        out.append(bh.merge_behaviors(r, m, None))
                    else:
                        out.append(bh.merge_behaviors(m, r, None))
                    del self.rows[:2]
                    self.skip = 1  # idx += 2 then += 1: the row after the pair is not examined
                    continue
                self.stopped = True
                continue
            out.append(self.rows.pop(0))
        return out


def behavior_pairs(test: Callable[[Row, Row], bool], label: int | None) -> Callable:
    """A refinement pair decision: merge (MergeLowLevelBehaviors) when `test` accepts."""

    def decide(r: Row, m: Row) -> Row | None:
        if test(r, m):
            return bh.merge_behaviors(r, m, label)
        return None

    return decide


class RepeatedBehaviors(Op):
    """Refinement step 4: runs of equal labels, merged pairwise pass after pass until one row.

    The passes pair (1,2), (3,4), ... then the results again: a binary counter of complete
    blocks, whose leftovers fold right to left at the end of the run (O(log run) rows held).
    """

    def __init__(self) -> None:
        self.blocks: list[Row | None] = []  # blocks[k]: a merged block of 2**k rows
        self.label: int | None = None

    def _flush(self) -> list[Row]:
        carry: Row | None = None
        for block in self.blocks:  # low to high = right to left
            if block is None:
                continue
            carry = block if carry is None else bh.merge_behaviors(block, carry, None)
        self.blocks = []
        self.label = None
        return [carry] if carry is not None else []

    def push(self, row: Row) -> list[Row]:
        out: list[Row] = []
        if self.label is not None and row[bh.B_LBL] != self.label:
            out = self._flush()
        self.label = row[bh.B_LBL]
        carry, k = row, 0
        while k < len(self.blocks) and self.blocks[k] is not None:
            carry = bh.merge_behaviors(self.blocks[k], carry, None)  # type: ignore[arg-type]
            self.blocks[k] = None
            k += 1
        if k == len(self.blocks):
            self.blocks.append(carry)
        else:
            self.blocks[k] = carry
        return out

    def finish(self) -> list[Row]:
        return self._flush()

    def retained(self) -> int:
        return sum(b is not None for b in self.blocks)


# --------------------------------------------------------------------------- the chain


class Chain(Op):
    """Operators in sequence; rows leaving one enter the next."""

    def __init__(self, ops: list[Op]) -> None:
        self.ops = ops

    def _through(self, rows: list[Row], start: int) -> list[Row]:
        for op in self.ops[start:]:
            nxt: list[Row] = []
            for r in rows:
                nxt.extend(op.push(r))
            rows = nxt
            if not rows:
                break
        return rows

    def push(self, row: Row) -> list[Row]:
        return self._through([row], 0)

    def poll(self) -> list[Row]:
        out: list[Row] = []
        for k, op in enumerate(self.ops):
            rows = op.poll()
            if rows:
                out.extend(self._through(rows, k + 1))
        return out

    def finish(self) -> list[Row]:
        out: list[Row] = []
        for k, op in enumerate(self.ops):
            rows = op.finish()
            if rows:
                out.extend(self._through(rows, k + 1))
        return out

    def retained(self) -> int:
        return sum(op.retained() for op in self.ops)

    def push_rows(self, rows: list[Row]) -> list[Row]:
        """Several final rows at once, operator after operator (same rows as pushing each)."""
        for op in self.ops:
            if not rows:
                break
            push = op.push
            out: list[Row] = []
            for r in rows:
                out.extend(push(r))
            rows = out
        return rows

    def run_all(self, rows: list[Row]) -> list[Row]:
        """A complete sequence, operator after operator (same rows as push + finish)."""
        for op in self.ops:
            push = op.push
            out: list[Row] = []
            for r in rows:
                out.extend(push(r))
            out.extend(op.finish())
            rows = out
        return rows


def _labels(*labels: int, field: int) -> Callable[[Row], bool]:
    """can_start predicate: the row's label is one that can open a merging pair."""
    allowed = frozenset(labels)
    return lambda row: row[field] in allowed


def primitive_durations_pass(config: TaxonomyConfig) -> PairPass:
    """Clean-up step 2 (impulses never open a pair)."""
    return PairPass(
        lambda a, b: pr.duration_pair(a, b, config),
        can_start=lambda row: row[pr.LABEL] not in (pr.PIMP, pr.NIMP),
    )


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
        PairPass(adjust, cycle.before_start, _labels(mc.A, mc.I, mc.D, field=mc.LBL)),
        PairPass(constant, cycle.before_start, _labels(mc.I, mc.K, mc.D, field=mc.LBL)),
    ]


def _push_pull(w1: float, w2: float) -> Callable[[Row, Row], bool]:
    def test(r: Row, m: Row) -> bool:  # both similarity tests use the amplitude [bug]
        return (
            {r[bh.B_LBL], m[bh.B_LBL]} == {bh.PS, bh.PL}
            and mc.similar(r[bh.B_AMP], m[bh.B_AMP], w1)
            and mc.similar(r[bh.B_AMP], m[bh.B_AMP], w2)
        )

    return test


def _align_shift(r: Row, m: Row) -> bool:
    return (
        r[bh.B_LBL] in (bh.SH, bh.AL)
        and m[bh.B_LBL] in (bh.SH, bh.AL)
        and m[bh.B_AMP] < r[bh.B_AMP]
    )


def _align_push(wa: float, wm: float) -> Callable[[Row, Row], bool]:
    def test(r: Row, m: Row) -> bool:  # the reverse order can never be true in the original
        return (
            r[bh.B_LBL] in (bh.AL, bh.SH)
            and m[bh.B_LBL] in (bh.PS, bh.PL)
            and mc.similar(r[bh.B_AMP], m[bh.B_AMP], wa)
            and mc.similar(r[bh.B_MAG], m[bh.B_MAG], wm)
        )

    return test


_MOVES = (bh.PS, bh.PL, bh.AL, bh.SH)


def _fixed(fa: float, fm: float) -> Callable[[Row, Row], bool]:
    def test(r: Row, m: Row) -> bool:
        return (
            (r[bh.B_LBL] == bh.FX and m[bh.B_LBL] in _MOVES)
            or (m[bh.B_LBL] == bh.FX and r[bh.B_LBL] in _MOVES)
        ) and (
            mc.similar(r[bh.B_AMP], m[bh.B_AMP], fa) and mc.similar(r[bh.B_MAG], m[bh.B_MAG], fm)
        )

    return test


def refinement_cycle(config: TaxonomyConfig) -> list[Op]:
    """One Refinement.m call as six operators."""
    first = bh.B_LBL
    return [
        BehaviorDurations(config),
        PairPass(
            behavior_pairs(_push_pull(*config.push_pull_similarity), bh.AL),
            can_start=_labels(bh.PS, bh.PL, field=first),
        ),
        PairPass(behavior_pairs(_align_shift, bh.AL), can_start=_labels(bh.SH, bh.AL, field=first)),
        RepeatedBehaviors(),
        PairPass(
            behavior_pairs(_align_push(*config.align_push_similarity), bh.AL),
            can_start=_labels(bh.AL, bh.SH, field=first),
        ),
        PairPass(
            behavior_pairs(_fixed(*config.fixed_similarity), bh.FX),
            can_start=_labels(bh.FX, *_MOVES, field=first),
        ),
    ]


class AxisPipeline:
    """Labelled primitives of one axis in; final MC and LLB rows out, in order."""

    def __init__(self, ctx: StreamContext) -> None:
        cfg = ctx.config
        self.ctx = ctx
        prim_ops: list[Op] = []
        if cfg.primitive_cleanup:
            prim_ops = [RepeatedPrimitives(), primitive_durations_pass(cfg)]
        mc_ops: list[Op] = [Compose(cfg)]
        for _ in range(cfg.composition_cleanup_cycles):
            mc_ops.extend(composition_cycle(ctx))
        llb_ops: list[Op] = [ComposeBehaviors(cfg)]
        for _ in range(cfg.behavior_refinement_cycles):
            llb_ops.extend(refinement_cycle(cfg))
        self.compositions = Chain(prim_ops + mc_ops)
        self.behaviors = Chain(llb_ops)
        self.held_last: Row | None = None  # final_segment=False drops the wrap-up segment

    def _flow(self, mcs: list[Row]) -> tuple[list[Row], list[Row]]:
        llbs: list[Row] = []
        for m in mcs:
            llbs.extend(self.behaviors.push(list(m)))
        return mcs, llbs

    def push(self, prim: Row) -> tuple[list[Row], list[Row]]:
        """A final labelled primitive in; the MCs and LLBs that became final out."""
        if not self.ctx.config.final_segment:
            prim, self.held_last = self.held_last, prim
            if prim is None:
                return [], []
        return self._flow(self.compositions.push(prim))

    def push_rows(self, prims: list[Row]) -> tuple[list[Row], list[Row]]:
        """Several final labelled primitives in (e.g. from push_many); final MCs and LLBs out."""
        if len(prims) == 1:
            return self.push(prims[0])
        if not self.ctx.config.final_segment:
            prims = [self.held_last, *prims] if self.held_last is not None else list(prims)
            self.held_last = prims.pop()
        mcs = self.compositions.push_rows(prims)
        return mcs, self.behaviors.push_rows([list(m) for m in mcs])

    def poll(self) -> tuple[list[Row], list[Row]]:
        """Rows released because time advanced or a boundary was marked."""
        mcs, llbs = self._flow(self.compositions.poll())
        llbs += self.behaviors.poll()
        return mcs, llbs

    def finish(self) -> tuple[list[Row], list[Row]]:
        mcs, llbs = self._flow(self.compositions.finish())
        return mcs, llbs + self.behaviors.finish()

    def retained(self) -> int:
        return self.compositions.retained() + self.behaviors.retained()

    def run_whole(self, prims: list[Row]) -> tuple[list[Row], list[Row]]:
        """A whole axis at once (the batch engine): the same operators, one after the other."""
        if not self.ctx.config.final_segment:
            prims = prims[:-1]
        mcs = self.compositions.run_all(prims)
        return mcs, self.behaviors.run_all([list(m) for m in mcs])


# --------------------------------------------------------------------------- whole lists


def run_ops(ops: list[Op], rows: list[Row]) -> list[Row]:
    """Push a whole list through operators and finish: a pass applied to a complete sequence."""
    return Chain(ops).run_all(rows)


def whole_context(
    config: TaxonomyConfig, state_times: Sequence[float], end_time: float
) -> StreamContext:
    """The context of a complete trial (every boundary and the end known)."""
    return StreamContext(
        config, boundaries=list(state_times), now=math.inf, ended=True, end_time=end_time
    )


def clean_primitives(prims: list[Row], config: TaxonomyConfig) -> list[Row]:
    """primitivesCleanUp.m on a whole axis."""
    return run_ops([RepeatedPrimitives(), primitive_durations_pass(config)], prims)


def compose(prims: list[Row], config: TaxonomyConfig) -> list[Row]:
    """CompoundMotionComposition's scan on a whole axis (before filtering)."""
    return run_ops([Compose(config)], prims)


def clean_compositions(
    mcs: list[Row], state_times: Sequence[float], end_time: float, config: TaxonomyConfig
) -> list[Row]:
    """cleanUp.m run composition_cleanup_cycles times on a whole axis."""
    ctx = whole_context(config, state_times, end_time)
    ops: list[Op] = []
    for _ in range(config.composition_cleanup_cycles):
        ops.extend(composition_cycle(ctx))
    return run_ops(ops, [list(m) for m in mcs])


def compose_behaviors(mcs: list[Row], config: TaxonomyConfig) -> list[Row]:
    """llbehComposition's scan on a whole axis (before refinement)."""
    return run_ops([ComposeBehaviors(config)], mcs)


def refine_behaviors(llbs: list[Row], config: TaxonomyConfig) -> list[Row]:
    """Refinement.m run behavior_refinement_cycles times on a whole axis."""
    ops: list[Op] = []
    for _ in range(config.behavior_refinement_cycles):
        ops.extend(refinement_cycle(config))
    return run_ops(ops, [list(b) for b in llbs])

"""The LLB layer's operators: llbehComposition's scan and Refinement.m's six steps (spec 2.4-2.5).

The rules (motCompsMatchEval, MergeLowLevelBehaviors) are in behaviors.py; these passes apply
them in the original order.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from rcbht_introspection.taxonomy import behaviors as bh
from rcbht_introspection.taxonomy import compositions as mc
from rcbht_introspection.taxonomy import primitives as pr
from rcbht_introspection.taxonomy.config import TaxonomyConfig
from rcbht_introspection.taxonomy.ops import BufferedOp, Op, PairPass, Row, label_in


class ComposeBehaviors(BufferedOp):
    """llbehComposition: the time flag is set once and never reset; 'a' may look two MCs ahead."""

    def __init__(self, config: TaxonomyConfig) -> None:
        self.config = config
        self.rows: list[Row] = []
        self.flag = False

    def oldest_end(self) -> float:
        return self.rows[0][mc.T2E] if self.rows else math.inf

    def resume(self, previous: Op) -> None:
        assert isinstance(previous, ComposeBehaviors)
        self.flag = previous.flag  # set once per trial, never reset

    def _step(self, ended: bool) -> list[Row]:
        """Emit LLBs while the lookahead the current MC needs (1 or 2 more) is there."""
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

    def oldest_end(self) -> float:
        return self.rows[0][bh.B_T2E] if self.rows else math.inf

    def resume(self, previous: Op) -> None:
        assert isinstance(previous, BehaviorDurations)
        self.stopped = previous.stopped

    def _step(self, ended: bool) -> list[Row]:
        """Decide pairs from the front until one needs more rows or the pass stops."""
        out: list[Row] = []
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
            if _duration_refinable(r, m):
                merged = self._merge_by_duration(r, m)
                if merged is None:
                    self.stopped = True
                    continue
                out.append(merged)
                del self.rows[:2]
                self.skip = 1  # idx += 2 then += 1: the row after the pair is not examined
                continue
            out.append(self.rows.pop(0))
        return out

    def _merge_by_duration(self, r: Row, m: Row) -> Row | None:
        """The pair merged into the longer one when their amplitudes are comparable and their
        durations differ by more than the ratio; None when the pass stops at this pair."""
        cfg = self.config
        ratio = pr.ieee_div(abs(m[bh.B_AMP]), abs(r[bh.B_AMP]))
        if ratio == 0 or ratio == math.inf or ratio > cfg.behavior_amplitude_ratio:
            return None
        if r[bh.B_MC2] != 6 and m[bh.B_MC2] != 6:
            p1, p2 = r[bh.B_T2E] - r[bh.B_T1S], m[bh.B_T2E] - m[bh.B_T1S]
        elif r[bh.B_MC2] == 6:
            p1, p2 = r[bh.B_T1E] - r[bh.B_T1S], m[bh.B_T2E] - m[bh.B_T1S]
        else:
            p1, p2 = r[bh.B_T2E] - r[bh.B_T1S], m[bh.B_T1E] - m[bh.B_T1S]
        d = pr.ieee_div(p1, p2)
        if d > cfg.behavior_duration_ratio:
            return bh.merge_behaviors(r, m, None)
        if d < 1 / cfg.behavior_duration_ratio:
            return bh.merge_behaviors(m, r, None)
        return None


def _duration_refinable(r: Row, m: Row) -> bool:
    """Step 1 examines a pair only when neither is a contact and neither ends in 'u' or 'z'."""
    return (
        r[bh.B_LBL] != bh.CT
        and m[bh.B_LBL] != bh.CT
        and r[bh.B_MC2] not in (mc.U, mc.Z)
        and m[bh.B_MC2] not in (mc.U, mc.Z)
    )


def behavior_pairs(
    test: Callable[[Row, Row], bool], label: int | None
) -> Callable[[Row, Row], Row | None]:
    """A refinement pair decision: merge (MergeLowLevelBehaviors) when `test` accepts."""

    def decide(r: Row, m: Row) -> Row | None:
        """Merge `m` into `r` and return `r` when `test` accepts, else None."""
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
        self.label: float | None = None
        self.last_end = math.inf  # end of the run's last row (inf: no run)

    def oldest_end(self) -> float:
        return self.last_end

    def _flush(self) -> list[Row]:
        """Fold the run's blocks right to left into one row and release it."""
        carry: Row | None = None
        for block in self.blocks:  # low to high = right to left
            if block is None:
                continue
            carry = block if carry is None else bh.merge_behaviors(block, carry, None)
        self.blocks = []
        self.label = None
        self.last_end = math.inf
        return [carry] if carry is not None else []

    def push(self, row: Row) -> list[Row]:
        out: list[Row] = []
        if self.label is not None and row[bh.B_LBL] != self.label:
            out = self._flush()
        self.label = row[bh.B_LBL]
        self.last_end = row[bh.B_T2E]
        carry, k = row, 0
        while k < len(self.blocks) and (block := self.blocks[k]) is not None:
            carry = bh.merge_behaviors(block, carry, None)
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


def _push_pull(w1: float, w2: float) -> Callable[[Row, Row], bool]:
    """Step 2 test: a push/pull pair of similar amplitude (twice, with w1 and w2)."""

    def test(r: Row, m: Row) -> bool:  # both similarity tests use the amplitude [bug]
        """Do r and m form a similar push-pull or pull-push pair?"""
        return (
            {r[bh.B_LBL], m[bh.B_LBL]} == {bh.PS, bh.PL}
            and mc.similar(r[bh.B_AMP], m[bh.B_AMP], w1)
            and mc.similar(r[bh.B_AMP], m[bh.B_AMP], w2)
        )

    return test


def _align_shift(r: Row, m: Row) -> bool:
    """Step 3 test: shift/align followed by a shift/align of smaller amplitude."""
    return (
        r[bh.B_LBL] in (bh.SH, bh.AL)
        and m[bh.B_LBL] in (bh.SH, bh.AL)
        and m[bh.B_AMP] < r[bh.B_AMP]
    )


def _align_push(wa: float, wm: float) -> Callable[[Row, Row], bool]:
    """Step 5 test: align/shift then push/pull with similar amplitude and magnitude."""

    def test(r: Row, m: Row) -> bool:  # the reverse order can never be true in the original
        """Does an align/shift r precede a similar push/pull m?"""
        return (
            r[bh.B_LBL] in (bh.AL, bh.SH)
            and m[bh.B_LBL] in (bh.PS, bh.PL)
            and mc.similar(r[bh.B_AMP], m[bh.B_AMP], wa)
            and mc.similar(r[bh.B_MAG], m[bh.B_MAG], wm)
        )

    return test


_MOVES = (bh.PS, bh.PL, bh.AL, bh.SH)


def _fixed(fa: float, fm: float) -> Callable[[Row, Row], bool]:
    """Step 6 test: FX beside a move, similar in amplitude and magnitude."""

    def test(r: Row, m: Row) -> bool:
        """Is one of r, m FX and the other a move, similar in amplitude and magnitude?"""
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
            can_start=label_in(bh.PS, bh.PL, field=first),
            end=bh.B_T2E,
        ),
        PairPass(
            behavior_pairs(_align_shift, bh.AL),
            can_start=label_in(bh.SH, bh.AL, field=first),
            end=bh.B_T2E,
        ),
        RepeatedBehaviors(),
        PairPass(
            behavior_pairs(_align_push(*config.align_push_similarity), bh.AL),
            can_start=label_in(bh.AL, bh.SH, field=first),
            end=bh.B_T2E,
        ),
        PairPass(
            behavior_pairs(_fixed(*config.fixed_similarity), bh.FX),
            can_start=label_in(bh.FX, *_MOVES, field=first),
            end=bh.B_T2E,
        ),
    ]

"""The operator machinery of the RCBHT upper layers: resumable left-to-right passes and chains.

Each pass of the original code is one operator with `push(row)` and `finish()` that returns a row
only once no later input can change it, so a chain emits exactly the rows that are final. The batch
engine pushes a whole axis and calls finish(); the streaming engine pushes rows as segments close.
Both therefore run the same code. The operators of each layer are in primitive_ops.py,
composition_ops.py and behavior_ops.py; pipeline.AxisPipeline chains them for one axis.

Whole-trial inputs of the reference algorithm reach the operators through `StreamContext`:
the sub-task start times (rotation start s2 -> startIndex; mating start -> the 'a'-chain time
limit), the time of the latest sample (a boundary is never marked later than the samples it
precedes, so unknown boundaries lie in the future) and, per MC cycle, the largest amplitude of
step 3 (final once that pass stops).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from rcbht_introspection.taxonomy.compositions import state_limits
from rcbht_introspection.taxonomy.config import TaxonomyConfig

Row = list[float]


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
    _limit_key: tuple[int, bool, float] | tuple[()] = ()
    _limit: float | None = None
    waiting: set[Op] = field(default_factory=set)
    """Operators waiting for time to pass (the 'a'-chain limit); poll them as samples arrive."""
    bound: float | None = None
    """Finality bound in seconds (live profile, pipeline.AxisPipeline): a chain holding a row
    whose end is before now - bound ends its sequence there. None = unbounded look-ahead."""

    def cutoff(self) -> float:
        """Rows ending before this time may no longer be held (-inf when unbounded)."""
        return -math.inf if self.bound is None else self.now - self.bound

    @property
    def s2(self) -> float | None:
        """The rotation start (cleanUp's startIndex time), once marked."""
        return self.boundaries[1] if len(self.boundaries) > 1 else None

    def limit(self) -> float | None:
        """The 'a'-chain time limit (cleanUp stateVec(2,2)) if it is already determined."""
        key = (len(self.boundaries), self.ended, self.end_time)
        if key != self._limit_key:
            known = len(self.boundaries) >= 4 or self.ended
            self._limit = state_limits(self.boundaries, self.end_time)[1] if known else None
            self._limit_key = key
        return self._limit


class Op:
    """One resumable pass: push final input rows, receive final output rows."""

    def push(self, row: Row) -> list[Row]:
        """A final input row in; the output rows that became final out."""
        raise NotImplementedError

    def finish(self) -> list[Row]:
        """The end of the input: every row still held, now final."""
        return []

    def retained(self) -> int:
        """Rows held back (for the bounded-memory check)."""
        return 0

    def poll(self) -> list[Row]:
        """Rows that became final without new input (e.g. when time advanced)."""
        return []

    def oldest_end(self) -> float:
        """End time of the oldest row held back (inf when none), for the finality bound."""
        return math.inf

    def resume(self, previous: Op) -> None:
        """Take over the trial-long state of `previous`, the same pass before a finality cut
        (e.g. a pass that stopped for good stays stopped); most passes have none."""


class BufferedOp(Op):
    """A pass that buffers rows and decides in `_step(ended)` how many it can release."""

    rows: list[Row]

    def _step(self, ended: bool) -> list[Row]:
        """Release the buffered rows that are final (all of them once `ended`)."""
        raise NotImplementedError

    def push(self, row: Row) -> list[Row]:
        self.rows.append(row)
        return self._step(False)

    def finish(self) -> list[Row]:
        return self._step(True)

    def retained(self) -> int:
        return len(self.rows)


class HoldsOneRow(Op):
    """An operator that holds at most one row back (`pending`); the end releases it.
    `end` is the index of a row's end time (for oldest_end)."""

    pending: Row | None = None
    end: int | None = None

    def oldest_end(self) -> float:
        row = self.pending
        return math.inf if row is None or self.end is None else row[self.end]

    def finish(self) -> list[Row]:
        out = [self.pending] if self.pending is not None else []
        self.pending = None
        return out

    def retained(self) -> int:
        return 1 if self.pending is not None else 0


class PairPass(HoldsOneRow):
    """A greedy left-to-right pass over pairs (i, i+1); a merged pair is not compared again.

    `decide(a, b)` returns the merged row or None. Rows before `start(pos)` pass through, and so
    does a row that `can_start` says can never be the first of a merging pair (it waits for no
    one: the previous pair was already decided without it). `end`: the index of a row's end time.
    """

    def __init__(
        self,
        decide: Callable[[Row, Row], Row | None],
        start: Callable[[int], bool] | None = None,
        can_start: Callable[[Row], bool] | None = None,
        end: int | None = None,
    ) -> None:
        self.decide = decide
        self.before_start = start
        self.can_start = can_start
        self.end = end
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


class Chain(Op):
    """Operators in sequence; rows leaving one enter the next."""

    def __init__(self, ops: list[Op]) -> None:
        self.ops = ops

    def _through(self, rows: list[Row], start: int) -> list[Row]:
        """Push `rows` through the operators from index `start` on."""
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

    def oldest_end(self) -> float:
        return min(op.oldest_end() for op in self.ops)

    def resume(self, previous: Op) -> None:
        assert isinstance(previous, Chain) and len(previous.ops) == len(self.ops)
        for op, old in zip(self.ops, previous.ops, strict=True):
            op.resume(old)

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


def label_in(*labels: int, field: int) -> Callable[[Row], bool]:
    """A PairPass can_start predicate: the row's label (at index `field`) can open a merging pair."""
    allowed = frozenset(labels)
    return lambda row: row[field] in allowed


def run_ops(ops: list[Op], rows: list[Row]) -> list[Row]:
    """Push a whole list through operators and finish: a pass applied to a complete sequence."""
    return Chain(ops).run_all(rows)

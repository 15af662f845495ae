"""Primitive clean-up (primitivesCleanUp.m, spec 2.1) as operators over primitive records.

The rules (merge_pair, duration_pair) are in primitives.py; these passes apply them in order.
"""

from __future__ import annotations

import math

from rcbht_introspection.taxonomy import primitives as pr
from rcbht_introspection.taxonomy.config import TaxonomyConfig
from rcbht_introspection.taxonomy.ops import Op, PairPass, Row


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
        """Merge the held run (MergePrimitives, when longer than one row) and release it."""
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

    def oldest_end(self) -> float:
        return math.inf if self.last is None else self.last[pr.FINISH]

    def retained(self) -> int:
        return 1 if self.first is not None else 0


def primitive_durations_pass(config: TaxonomyConfig) -> PairPass:
    """Clean-up step 2 (impulses never open a pair)."""
    return PairPass(
        lambda a, b: pr.duration_pair(a, b, config),
        can_start=lambda row: row[pr.LABEL] not in (pr.PIMP, pr.NIMP),
        end=pr.FINISH,
    )

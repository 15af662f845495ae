"""A chain of passes under a finality bound: rows decided with all the look-ahead of the bound.

EXPERIMENT (replay): at a cut, the chain is finished as if the trial ended now; only the outputs
holding an input older than the cutoff are committed, and the younger inputs are replayed into a
fresh chain, so they keep their look-ahead.
"""

from __future__ import annotations

from collections.abc import Callable

from rcbht_introspection.taxonomy.ops import Chain, Row, StreamContext


class BoundedChain:
    """Rows of one level in, final rows of the next out, none held past the bound."""

    def __init__(
        self,
        build: Callable[[], Chain],
        ctx: StreamContext,
        in_end: int,
        out_start: int,
        out_end: int,
    ) -> None:
        self.build, self.ctx = build, ctx
        self.in_end, self.out_start, self.out_end = in_end, out_start, out_end
        self.chain = build()
        self.inputs: list[Row] = []  # pristine copies of the inputs not yet in a final output

    def _released(self, out: list[Row]) -> list[Row]:
        """Final outputs: forget the inputs they cover."""
        if out:
            last = out[-1][self.out_end] + 1e-9
            self.inputs = [x for x in self.inputs if x[self.in_end] > last]
        return out

    def push_rows(self, rows: list[Row]) -> list[Row]:
        self.inputs.extend(list(r) for r in rows)
        return self._released(self.chain.push_rows(rows)) + self._cut()

    def poll(self) -> list[Row]:
        return self._released(self.chain.poll()) + self._cut()

    def finish(self) -> list[Row]:
        self.inputs = []
        return self.chain.finish()

    def retained(self) -> int:
        return self.chain.retained() + len(self.inputs)

    def _cut(self) -> list[Row]:
        out: list[Row] = []
        cutoff = self.ctx.cutoff()
        while self.chain.oldest_end() < cutoff:
            outs = self.chain.finish()
            old = [x[self.in_end] for x in self.inputs if x[self.in_end] < cutoff]
            e_star = max(old) if old else cutoff
            commit = [o for o in outs if o[self.out_start] < e_star] or outs
            out.extend(self._released(commit))
            fresh = self.build()
            fresh.resume(self.chain)
            self.chain = fresh
            out.extend(self._released(fresh.push_rows([list(x) for x in self.inputs])))
        return out

"""One axis of the RCBHT upper layers: the operator chains of all three layers in order.

The primitive clean-up (primitive_ops.py), the MC layer and its filter cycles (composition_ops.py)
and the LLB layer and its refinement cycles (behavior_ops.py) run as one `Chain` per level; the
batch and the streaming engine both drive this class, so the rows come out identical to the
original whole-sequence passes.

With a finality bound (the `live` stream profile, StreamContext.bound), a chain that holds a row
whose end is older than now - bound is finished there, as if the trial ended, and replaced by a
fresh one that keeps the passes' trial-long state: every word is final at most the bound (plus one
window step) after its end.
"""

from __future__ import annotations

import math

from rcbht_introspection.taxonomy.behavior_ops import ComposeBehaviors, refinement_cycle
from rcbht_introspection.taxonomy.composition_ops import Compose, composition_cycle
from rcbht_introspection.taxonomy.ops import Chain, Op, Row, StreamContext
from rcbht_introspection.taxonomy.primitive_ops import RepeatedPrimitives, primitive_durations_pass


class AxisPipeline:
    """Labelled primitives of one axis in; final MC and LLB rows out, in order."""

    def __init__(self, ctx: StreamContext) -> None:
        self.ctx = ctx
        self.compositions = self._composition_chain()
        self.behaviors = self._behavior_chain()
        self.held_last: Row | None = None  # final_segment=False drops the wrap-up segment
        self.oldest = (math.inf, math.inf)  # end of the oldest row each chain holds

    def _composition_chain(self) -> Chain:
        """The primitive clean-up, the MC scan and its filter cycles."""
        cfg = self.ctx.config
        prim_ops: list[Op] = []
        if cfg.primitive_cleanup:
            prim_ops = [RepeatedPrimitives(), primitive_durations_pass(cfg)]
        mc_ops: list[Op] = [Compose(cfg)]
        for _ in range(cfg.composition_cleanup_cycles):
            mc_ops.extend(composition_cycle(self.ctx))
        return Chain(prim_ops + mc_ops)

    def _behavior_chain(self) -> Chain:
        """The LLB scan and the refinement cycles."""
        cfg = self.ctx.config
        llb_ops: list[Op] = [ComposeBehaviors(cfg)]
        for _ in range(cfg.behavior_refinement_cycles):
            llb_ops.extend(refinement_cycle(cfg))
        return Chain(llb_ops)

    def _cut(
        self, mcs: list[Row], llbs: list[Row], changed: bool = True
    ) -> tuple[list[Row], list[Row]]:
        """Bounded finality: a chain holding a row that ended before now - bound ends its
        sequence there (every held row decided as at the end of a trial) and starts afresh,
        keeping only the passes' trial-long state (Op.resume)."""
        if self.ctx.bound is None:
            return mcs, llbs
        cutoff = self.ctx.cutoff()
        if changed:  # rows moved: the chains' oldest held ends are looked up again
            self.oldest = (self.compositions.oldest_end(), self.behaviors.oldest_end())
        if self.oldest[0] < cutoff:
            more = self.compositions.finish()
            fresh = self._composition_chain()
            fresh.resume(self.compositions)
            self.compositions = fresh
            mcs = mcs + more
            for m in more:
                llbs = llbs + self.behaviors.push(list(m))
            self.oldest = (math.inf, self.behaviors.oldest_end())
        if self.oldest[1] < cutoff:
            llbs = llbs + self.behaviors.finish()
            fresh = self._behavior_chain()
            fresh.resume(self.behaviors)
            self.behaviors = fresh
            self.oldest = (self.oldest[0], math.inf)
        return mcs, llbs

    def _flow(self, mcs: list[Row]) -> tuple[list[Row], list[Row]]:
        """Feed final MCs to the LLB chain; return them with the LLBs that became final."""
        llbs: list[Row] = []
        for m in mcs:
            llbs.extend(self.behaviors.push(list(m)))
        return mcs, llbs

    def push(self, prim: Row) -> tuple[list[Row], list[Row]]:
        """A final labelled primitive in; the MCs and LLBs that became final out."""
        if not self.ctx.config.final_segment:
            held, self.held_last = self.held_last, prim
            if held is None:
                return [], []
            return self._cut(*self._flow(self.compositions.push(held)))
        return self._cut(*self._flow(self.compositions.push(prim)))

    def push_rows(self, prims: list[Row]) -> tuple[list[Row], list[Row]]:
        """Several final labelled primitives in (e.g. from push_many); final MCs and LLBs out."""
        if len(prims) == 1:
            return self.push(prims[0])
        if not self.ctx.config.final_segment:
            prims = [self.held_last, *prims] if self.held_last is not None else list(prims)
            self.held_last = prims.pop()
        mcs = self.compositions.push_rows(prims)
        return self._cut(mcs, self.behaviors.push_rows([list(m) for m in mcs]))

    def poll(self) -> tuple[list[Row], list[Row]]:
        """Rows released because time advanced or a boundary was marked."""
        mcs, llbs = self._flow(self.compositions.poll())
        llbs += self.behaviors.poll()
        return self._cut(mcs, llbs)

    def expire(self) -> tuple[list[Row], list[Row]]:
        """Rows released because time advanced past the finality bound of a held row."""
        return self._cut([], [], changed=False)

    def finish(self) -> tuple[list[Row], list[Row]]:
        """The end of the axis: every held MC and LLB."""
        mcs, llbs = self._flow(self.compositions.finish())
        return mcs, llbs + self.behaviors.finish()

    def retained(self) -> int:
        """Rows held back by both chains (for the bounded-memory check)."""
        return self.compositions.retained() + self.behaviors.retained()

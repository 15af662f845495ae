"""Low-level-behaviour (LLB) layer (spec 2.4, llbehComposition.m) and refinement (spec 2.5).

An LLB record is a list in the original `llbehStruc` layout: [label, avgVal1, avgVal2, AVG_MAG,
rms1, rms2, AVG_RMS, amp1, amp2, AVG_AMP, mc1, mc2, t1Start, t1End, t2Start, t2End, tAvg], labels
as integers (FX CT PS PL AL SH U N = 1..8; mc1/mc2 are MC integers a..z = 1..10, or after a merge
the LLB integer [bug], which the files print through the MC table). Here: the LLB record of an MC
(pair), the motCompsMatchEval rules and MergeLowLevelBehaviors; the passes are behavior_ops.py's.
"""

from __future__ import annotations

from collections.abc import Sequence

from rcbht_introspection.taxonomy.compositions import (
    AMP,
    AVGV,
    LBL,
    RMS,
    T1E,
    T1S,
    T2E,
    T2S,
    TAVG,
    Composition,
)
from rcbht_introspection.taxonomy.compositions import NC as MC_NC
from rcbht_introspection.taxonomy.compositions import PC as MC_PC
from rcbht_introspection.taxonomy.compositions import A as MC_A
from rcbht_introspection.taxonomy.compositions import C as MC_C
from rcbht_introspection.taxonomy.compositions import D as MC_D
from rcbht_introspection.taxonomy.compositions import I as MC_I
from rcbht_introspection.taxonomy.compositions import K as MC_K
from rcbht_introspection.taxonomy.compositions import N as MC_N
from rcbht_introspection.taxonomy.compositions import Z as MC_Z
from rcbht_introspection.taxonomy.words import BEHAVIOR_LABELS, COMPOSITION_LABELS, Level, Word

FX, CT, PS, PL, AL, SH, U, N = range(1, 9)
"""LLB label integers."""
(B_LBL, B_AVG1, B_AVG2, B_MAG, B_RMS1, B_RMS2, B_RMS, B_AMP1, B_AMP2, B_AMP,
 B_MC1, B_MC2, B_T1S, B_T1E, B_T2S, B_T2E, B_TAVG) = range(17)  # fmt: skip
"""Field indices of an LLB record."""

Behavior = list[float]


def _pair(label: int, m1: Composition, m2: Composition) -> Behavior:
    """A two-MC LLB record (motCompsMatchEval, 'compositions with a match')."""
    return [
        label, m1[AVGV], m2[AVGV], (m1[AVGV] + m2[AVGV]) / 2,
        m1[RMS], m2[RMS], max(m1[RMS], m2[RMS]),
        m1[AMP], m2[AMP], max(m1[AMP], m2[AMP]),
        m1[LBL], m2[LBL], m1[T1S], m1[T2E], m2[T1S], m2[T2E], (m1[TAVG] + m2[TAVG]) / 2,
    ]  # fmt: skip


def _single(label: int, m: Composition, mc2: int) -> Behavior:
    """A single-MC LLB: its values three times, the MC's own four times, mc2 = 'z' or 'n'."""
    avg, rms, amp = m[AVGV], m[RMS], m[AMP]
    return [
        label, avg, avg, avg, rms, rms, rms, amp, amp, amp, m[LBL], mc2,
        m[T1S], m[T1E], m[T2S], m[T2E], (m[T1S] + m[T2E]) / 2,
    ]  # fmt: skip


def match_compositions(
    mcs: Sequence[Composition], index: int, flag: bool, window: int
) -> tuple[Behavior, int]:
    """motCompsMatchEval for the MC at `index` (0-based): the LLB and the next index to examine."""
    n = len(mcs)
    cur = mcs[index]
    lbl = cur[LBL]
    last = index == n - 1
    next_index = index if last else index + 1
    rng = next_index if last else min(index + 1 + window, n - 1)
    if lbl in (MC_K, MC_I, MC_D):
        kind = {MC_K: FX, MC_I: PS, MC_D: PL}[int(lbl)]
        other = mcs[next_index]
        if other[LBL] == lbl:
            return _pair(kind, cur, other), next_index + 1
        return _single(kind if flag else N, cur, MC_Z), index + 1
    if lbl in (MC_C, MC_PC, MC_NC):
        other = mcs[next_index]
        o = other[LBL]
        if o == MC_C or (lbl == MC_PC and o == MC_NC) or (lbl == MC_NC and o == MC_PC):
            return _pair(CT, cur, other), next_index + 1
        return _single(CT, cur, MC_Z), index + 1
    if lbl == MC_A:
        if cur[T2E] - cur[T1S] > 0.1:
            rng = next_index
        for match in range(next_index, rng + 1):
            other = mcs[match]
            if other[LBL] == MC_A:
                kind = AL if other[AMP] < cur[AMP] else SH
                return _pair(kind, cur, other), match + 1
        return _single(AL if flag else N, cur, MC_Z), index + 1
    return _single(N, cur, MC_N), index + 1


# --------------------------------------------------------------------------- refinement


def merge_behaviors(r: Behavior, m: Behavior, label: int | None) -> Behavior:
    """MergeLowLevelBehaviors: the next LLB `m` into `r`, which it returns (only the original's
    first branch ever runs); label = `label` unless None."""
    if label is not None:
        r[B_LBL] = label
    r[B_AVG2] = m[B_AVG2]
    r[B_MAG] = (r[B_MAG] + m[B_MAG]) / 2
    r[B_RMS1] = max(r[B_RMS1], r[B_RMS2])
    r[B_RMS] = max(r[B_RMS], m[B_RMS])
    r[B_AMP2] = m[B_AMP2]
    r[B_AMP] = max(r[B_AMP], m[B_AMP])
    r[B_MC1] = r[B_MC2] = r[B_LBL]
    r[B_T1E] = r[B_T2E]
    r[B_T2S] = m[B_T1S]
    r[B_T2E] = m[B_T2E]
    if m[B_T2E] == r[B_T1S]:
        r[B_T1S] = m[B_T1S]
    if r[B_T1E] > r[B_T2E]:
        r[B_T2E] = r[B_T1E]
    if r[B_T2S] < r[B_T1S]:
        r[B_T1S] = r[B_T2S]
    if r[B_T2E] < m[B_T1S]:
        r[B_T1S] = r[B_T2S]
    r[B_TAVG] = (r[B_T1S] + r[B_T2E]) / 2
    return r


def behavior_word(b: Behavior, axis: str, arm: str, seq: int = 0) -> Word:
    """An LLB record as a Word with the llBehaviors keys (mc1/mc2 printed via the MC table)."""
    return Word(
        axis=axis, level=Level.BEHAVIOR, label=BEHAVIOR_LABELS[int(b[B_LBL]) - 1],
        start=b[B_T1S], end=b[B_T2E], arm=arm, seq=seq,
        sublabels=(COMPOSITION_LABELS[int(b[B_MC1]) - 1], COMPOSITION_LABELS[int(b[B_MC2]) - 1]),
        features={"averageVal1": b[B_AVG1], "averageVal2": b[B_AVG2], "AVG_MAG_VAL": b[B_MAG],
                  "rmsVal1": b[B_RMS1], "rmsVal2": b[B_RMS2], "AVG_RMS_Val": b[B_RMS],
                  "amplitudeVal1": b[B_AMP1], "amplitudeVal2": b[B_AMP2], "AVG_AMP_VAL": b[B_AMP],
                  "t1Start": b[B_T1S], "t1End": b[B_T1E], "t2Start": b[B_T2S], "t2End": b[B_T2E],
                  "tAvgIndex": b[B_TAVG]},
    )  # fmt: skip

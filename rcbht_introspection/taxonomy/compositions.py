"""Motion-composition (MC) layer (spec 2.2) and the rules of MC filtering (spec 2.3, cleanUp.m).

An MC record is a list in the original `motComps` layout: [label, avgVal, rmsVal, amplitude,
glabel1, glabel2, t1Start, t1End, t2Start, t2End, tAvg], labels as 1-based integers
(a i d k pc nc c u n z = 1..10; glabels are primitive integers). Here: the rule table, the MC
record of a primitive pair, similarity, the merges (MergeCompositions, the 'a'-chain merge), the
relabelling and the label pairs of the filter steps, and the sub-task limits; the passes that
apply them in the original order are the operators of composition_ops.py.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from rcbht_introspection.taxonomy.config import TaxonomyConfig
from rcbht_introspection.taxonomy.primitives import (
    AVG,
    CONS,
    FINISH,
    LABEL,
    MAX,
    MIN,
    MNEG,
    MPOS,
    NEGATIVE,
    NIMP,
    PIMP,
    POSITIVE,
    START,
    Primitive,
    ieee_div,
    running_sum,
)
from rcbht_introspection.taxonomy.words import COMPOSITION_LABELS, PRIMITIVE_LABELS, Level, Word

A, I, D, K, PC, NC, C, U, N, Z = range(1, 11)  # noqa: E741  (the original's letters)
"""MC label integers."""
LBL, AVGV, RMS, AMP, GL1, GL2, T1S, T1E, T2S, T2E, TAVG = range(11)
"""Field indices of an MC record."""
CONTACTS = frozenset({PC, NC, C})

Composition = list[float]

# Primitive classes used by the rule table.
_POS, _NEG, _CONS, _PIMP, _NIMP = "pos", "neg", "cons", "pimp", "nimp"


def primitive_class(label: float) -> str | None:
    """The rule-table class of a primitive label (None for 'none')."""
    if label in POSITIVE:
        return _POS
    if label in NEGATIVE:
        return _NEG
    if label == CONS:
        return _CONS
    if label == PIMP:
        return _PIMP
    if label == NIMP:
        return _NIMP
    return None


# (class1, class2) -> (pair label, single label or None if not ratio-gated, glabel substitutes,
# amplitude kind: "span" = |P2.max - P1.min|, "range" = max - min over both)
RULES: dict[tuple[str, str], tuple[int, int | None, tuple[int | None, int | None], str]] = {
    (_POS, _POS): (I, I, (None, None), "span"),
    (_POS, _NEG): (A, I, (None, None), "range"),
    (_POS, _CONS): (I, I, (None, None), "span"),
    (_POS, _PIMP): (PC, None, (None, None), "span"),
    (_POS, _NIMP): (NC, None, (None, None), "span"),
    (_NEG, _POS): (A, D, (None, None), "span"),
    (_NEG, _NEG): (D, D, (None, None), "range"),
    (_NEG, _CONS): (D, D, (None, None), "range"),
    (_NEG, _PIMP): (PC, None, (None, None), "range"),
    (_NEG, _NIMP): (NC, None, (None, None), "range"),
    (_CONS, _POS): (I, K, (CONS, MPOS), "span"),
    (_CONS, _NEG): (D, K, (CONS, MNEG), "range"),
    (_CONS, _CONS): (K, K, (None, None), "range"),
    (_CONS, _PIMP): (PC, None, (None, None), "range"),
    (_CONS, _NIMP): (NC, None, (None, None), "range"),
    (_PIMP, _POS): (PC, None, (PIMP, MPOS), "span"),
    (_PIMP, _NEG): (C, None, (PIMP, MNEG), "range"),
    (_PIMP, _CONS): (PC, None, (PIMP, CONS), "span"),
    (_PIMP, _PIMP): (PC, None, (PIMP, MPOS), "span"),
    (_PIMP, _NIMP): (C, None, (PIMP, NIMP), "range"),
    (_NIMP, _POS): (C, None, (NIMP, MPOS), "span"),
    (_NIMP, _NEG): (NC, None, (NIMP, MNEG), "range"),
    (_NIMP, _CONS): (NC, None, (NIMP, CONS), "range"),
    (_NIMP, _PIMP): (C, None, (NIMP, PIMP), "span"),
    (_NIMP, _NIMP): (NC, None, (NIMP, NIMP), "range"),
}
"""The complete MC rule table of spec 2.2 (final code, not the doc table)."""


def match_primitives(
    p1: Primitive, p2: Primitive, config: TaxonomyConfig
) -> tuple[Composition, bool]:
    """primMatchEval for one pair: the MC and whether it consumed P2 (False = single MC of P1)."""
    c1, c2 = primitive_class(p1[LABEL]), primitive_class(p2[LABEL])
    if c1 is None or c2 is None:  # 'none' primitive: no rule; a single 'z' MC of P1
        amp = p1[MAX] - p1[MIN]
        return _single(p1, Z, amp), False
    pair_label, single_label, (sub1, sub2), kind = RULES[(c1, c2)]
    if kind == "span":
        amplitude = abs(p2[MAX] - p1[MIN])
    else:
        amplitude = abs(max(p1[MAX], p2[MAX]) - min(p1[MIN], p2[MIN]))
    if single_label is not None:
        amp_ratio = ieee_div(p2[MAX] - p2[MIN], p1[MAX] - p1[MIN])
        dur_ratio = ieee_div(p2[FINISH] - p2[START], p1[FINISH] - p1[START])
        a_lim, l_lim = config.composition_amplitude_ratio, config.composition_length_ratio
        if (
            amp_ratio == 0
            or amp_ratio == math.inf
            or amp_ratio > a_lim
            or amp_ratio < 1 / a_lim
            or dur_ratio > l_lim
            or dur_ratio < 1 / l_lim
        ):
            return _single(p1, single_label, amplitude), False
    g1 = sub1 if sub1 is not None else p1[LABEL]
    g2 = sub2 if sub2 is not None else p2[LABEL]
    t1s, t2e = p1[START], p2[FINISH]
    return [
        pair_label, (p1[AVG] + p2[AVG]) / 2, max(p1[MAX], p2[MAX]), amplitude, g1, g2,
        t1s, p1[FINISH], p2[START], t2e, (t1s + t2e) / 2,
    ], True  # fmt: skip


def _single(p1: Primitive, label: int, amplitude: float) -> Composition:
    """A single-primitive MC: P1's values, t1Start = t1End = start, t2Start = t2End = finish."""
    s, f = p1[START], p1[FINISH]
    return [label, p1[AVG], p1[MAX], amplitude, p1[LABEL], p1[LABEL], s, s, f, f, (s + f) / 2]


# --------------------------------------------------------------------------- filtering


def similar(x: float, y: float, width: float) -> bool:
    """computePercentageThresh: | |x| - |y| | <= width * |max(x, y)| (the signed max)."""
    return abs(abs(x) - abs(y)) <= width * abs(max(x, y))


def state_limits(state_times: Sequence[float], end_time: float) -> tuple[float | None, float]:
    """(rotation start s2 or None, the adjustment-merge time limit) from the sub-task starts.

    The original's stateData is the start times followed by the end of the data; the limit is
    mating start - 0.002 s when all four starts exist (stateVec(2,2) of cleanUp.m).
    """
    data = [*state_times, end_time]
    s2 = data[1] if len(data) > 1 and len(state_times) > 1 else None
    n_states = len(data) - 3
    if n_states > 0:
        limit = data[3] - 0.002
    elif n_states == 0:
        limit = data[2]
    elif n_states == -1:
        limit = data[1]
    else:
        limit = -math.inf
    return s2, limit


def merge_span(
    r: Composition,
    last: Composition,
    count: int,
    avg_sum: float,
    rms: float,
    amplitude: float | None,
    label: float | None,
) -> None:
    """Make `r` span the `count` MCs up to `last`: mean avgVal, the given rms/amplitude/label
    (None: kept) and `last`'s t2 half with t1End = t2End. Every MC merge is this plus its quirks."""
    if label is not None:
        r[LBL] = label
    r[AVGV] = avg_sum / count
    r[RMS] = rms
    if amplitude is not None:
        r[AMP] = amplitude
    r[T2E] = last[T2E]
    r[T2S] = last[T1S]
    r[T1E] = r[T2E]
    r[TAVG] = (r[T1S] + r[T2E]) / 2


def merge_compositions(
    r: Composition,
    last: Composition,
    count: int,
    avg_sum: float,
    rms_max: float,
    amp_max: float | None,
    label: float | None,
) -> None:
    """MergeCompositions(whatComposition = count - 1 >= 1) from the run's avgVal sum and maxima, so
    a run merges as it streams by; the pair form (count 2) also takes `last`'s glabel2."""
    merge_span(r, last, count, avg_sum, rms_max, amp_max, label)
    if count == 2:
        r[GL2] = last[GL2]


def merge_next(r: Composition, m: Composition, label: float | None, amplitude: bool) -> None:
    """MergeCompositions(whatComposition = 1): the next MC `m` into `r` (amplitude max if asked)."""
    amp = max(r[AMP], m[AMP]) if amplitude else None
    merge_compositions(r, m, 2, r[AVGV] + m[AVGV], max(r[RMS], m[RMS]), amp, label)


def merge_previous(r: Composition, m: Composition, label: float | None, amplitude: bool) -> None:
    """MergeCompositions(whatComposition = 0): the previous MC `m` into `r` (r's t2 half stays)."""
    if label is not None:
        r[LBL] = label
    r[AVGV] = (r[AVGV] + m[AVGV]) / 2
    r[RMS] = max(r[RMS], m[RMS])
    if amplitude:
        r[AMP] = max(r[AMP], m[AMP])
    r[GL1] = m[GL1]
    r[T2S] = r[T1S]
    r[T1E] = m[T2E]
    r[T1S] = m[T1S]
    r[TAVG] = (r[T1S] + r[T2E]) / 2


def merge_adjustment_chain(run: Sequence[Composition], offset: float, step: float) -> Composition:
    """cleanUp step 1: a chain of similar 'a' into its first MC (returned); unlike MergeCompositions
    rmsVal is the mean, glabels stay and the halves split at the middle (- offset, + step)."""
    r, last, k = run[0], run[-1], len(run)
    avg_sum = running_sum(x[AVGV] for x in run)
    rms = running_sum(x[RMS] for x in run) / k
    merge_span(r, last, k, avg_sum, rms, max(x[AMP] for x in run), A)
    r[T1E] = (last[T2E] + r[T1S]) / 2 - offset
    r[T2S] = r[T1E] + step
    return r


def relabel_from(glabel: float) -> int | None:
    """Step 3's MC label for a primitive label: pos i, neg d, pimp pc, nimp nc, cons k, else None."""
    if glabel in POSITIVE:
        return I
    if glabel in NEGATIVE:
        return D
    if glabel == PIMP:
        return PC
    if glabel == NIMP:
        return NC
    if glabel == CONS:
        return K
    return None


ADJUST_PAIRS = frozenset({(A, I), (A, D), (I, A), (D, A)})
"""Step 6: the label pairs that merge into 'a' when similar."""
CONSTANT_PAIRS = frozenset({(I, K), (K, I), (D, K), (K, D), (D, I), (I, D)})
"""Step 7: the label pairs that merge into 'k' when similar."""


def composition_word(m: Composition, axis: str, arm: str, seq: int = 0) -> Word:
    """An MC record as a Word with the Composites keys."""
    return Word(
        axis=axis, level=Level.COMPOSITION, label=COMPOSITION_LABELS[int(m[LBL]) - 1],
        start=m[T1S], end=m[T2E], arm=arm, seq=seq,
        sublabels=(PRIMITIVE_LABELS[int(m[GL1]) - 1], PRIMITIVE_LABELS[int(m[GL2]) - 1]),
        features={"Average Val": m[AVGV], "RMS Val": m[RMS], "Amplitude Val": m[AMP],
                  "t1Start": m[T1S], "t1End": m[T1E], "t2Start": m[T2S], "t2End": m[T2E],
                  "tAvgIndex": m[TAVG]},
    )  # fmt: skip

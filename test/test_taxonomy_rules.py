"""Every rule of the RCBHT layers on small hand-built inputs (spec 2.1-2.5).

The expected values are written out from the spec's tables, not derived from the code's tables.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np
import pytest
import references

from rcbht_introspection.taxonomy import behavior_ops as bops
from rcbht_introspection.taxonomy import behaviors as bh
from rcbht_introspection.taxonomy import composition_ops as cops
from rcbht_introspection.taxonomy import compositions as mc
from rcbht_introspection.taxonomy import ops
from rcbht_introspection.taxonomy import primitive_ops as pops
from rcbht_introspection.taxonomy import primitives as pr
from rcbht_introspection.taxonomy.config import TaxonomyConfig, load_taxonomy_config
from rcbht_introspection.taxonomy.words import BEHAVIOR_LABELS, COMPOSITION_LABELS, PRIMITIVE_LABELS

CFG = TaxonomyConfig()
P = {name: i + 1 for i, name in enumerate(PRIMITIVE_LABELS)}
M = {name: i + 1 for i, name in enumerate(COMPOSITION_LABELS)}
B = {name: i + 1 for i, name in enumerate(BEHAVIOR_LABELS)}


def prim(label: str, start: float, finish: float, vmax: float = 1.0, vmin: float = 0.0,
         avg: float | None = None, grad: float = 0.0) -> list:  # fmt: skip
    """A primitive record [avg, max, min, start, finish, gradient, label]."""
    return [(vmax + vmin) / 2 if avg is None else avg, vmax, vmin, start, finish, grad, P[label]]


def comp(label: str, t1s: float, t2e: float, amp: float = 1.0, avg: float = 1.0, rms: float = 1.0,
         g1: str = "cons", g2: str = "cons", t1e: float | None = None,
         t2s: float | None = None) -> list:  # fmt: skip
    """An MC record; by default a pair MC whose halves split its span in the middle."""
    mid = (t1s + t2e) / 2
    return [M[label], avg, rms, amp, P[g1], P[g2], t1s, mid if t1e is None else t1e,
            mid if t2s is None else t2s, t2e, (t1s + t2e) / 2]  # fmt: skip


def beh(label: str, t1s: float, t2e: float, amp: float = 1.0, mag: float = 1.0,
        mc2: str = "k") -> list:  # fmt: skip
    """An LLB record of two MCs (mc2 given) covering [t1s, t2e]."""
    mid = (t1s + t2e) / 2
    return [B[label], mag, mag, mag, 1.0, 1.0, 1.0, amp, amp, amp, M["k"], M[mc2],
            t1s, mid, mid, t2e, mid]  # fmt: skip


def cycle_op(kind: type, config: TaxonomyConfig = CFG, limit: float = 10.0, max_amp: float = 0.0):
    """One MC filter operator of a cleanUp call that starts at row 0 (with a given 'a' limit)."""
    ctx = ops.StreamContext(config, boundaries=[0.0, -1.0, 0.0, limit + 0.002], ended=True)
    cycle = cops.CycleState(start=0, start_known=True, max_amp=max_amp, max_amp_final=True)
    return kind(ctx, cycle), cycle


def run_cycle_op(kind: type, rows: list, **kw: object) -> list:
    op, _ = cycle_op(kind, **kw)  # type: ignore[arg-type]
    return ops.run_ops([op], [list(r) for r in rows])


def pair_pass(pairs: frozenset, widths: tuple[float, float], label: int, rows: list) -> list:
    cycle = cops.CycleState(start=0, start_known=True)
    op = ops.PairPass(cops.similar_pairs(pairs, widths, label), cycle.before_start)
    return ops.run_ops([op], [list(r) for r in rows])


def durations(rows: list) -> list:
    return ops.run_ops([ops.PairPass(lambda a, b: pr.duration_pair(a, b, CFG))], rows)


# --------------------------------------------------------------------------- config


def test_reference_profile_loads_every_constant_from_yaml() -> None:
    config = load_taxonomy_config("reference")
    assert config == replace(TaxonomyConfig(), profile="reference")
    assert config.gradient_thresholds == (70.0, 46.0, 23.0, 1.0, -1.0, -23.0, -46.0, -70.0)


def test_unknown_profile_is_a_one_line_error() -> None:
    from rcbht_introspection.errors import InputError

    with pytest.raises(InputError, match="unknown taxonomy profile 'nope'"):
        load_taxonomy_config("nope")


# --------------------------------------------------------------------------- primitives


@pytest.mark.parametrize(
    ("g", "label"),
    [(70, "pimp"), (69.9, "bpos"), (46, "bpos"), (45.9, "mpos"), (23, "mpos"), (22.9, "spos"),
     (1, "spos"), (0.99, "cons"), (0, "cons"), (-0.5, "cons"), (-1, "sneg"), (-22.9, "sneg"),
     (-23, "mneg"), (-45.9, "mneg"), (-46, "bneg"), (-69.9, "bneg"), (-70, "none"),
     (-70.1, "nimp")],
)  # fmt: skip
def test_gradient_classification_boundaries(g: float, label: str) -> None:
    assert PRIMITIVE_LABELS[pr.classify_gradient(g, CFG.gradient_thresholds) - 1] == label


def test_moment_axes_with_a_small_domain_use_tenth_thresholds() -> None:
    y = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8])
    domain = pr.axis_domain(y, CFG)  # 4th largest 0.5, 4th smallest 0.3
    assert domain == pytest.approx(1.02 * 0.5 + 0.98 * 0.3)
    assert pr.axis_thresholds("My", domain, CFG)[0] == pytest.approx(7.0)
    assert pr.axis_thresholds("Fx", domain, CFG)[0] == 70.0
    assert pr.axis_thresholds("Mz", 1.9, CFG)[0] == 70.0


def segments_of(y: np.ndarray, dt: float = 0.005) -> list[list[float]]:
    t = np.arange(len(y)) * dt
    return pr.segment_arrays(t, y.reshape(-1, 1), CFG).segments[0]


def test_a_straight_line_is_one_segment_with_its_slope() -> None:
    y = 10.0 * np.arange(101) * 0.005
    (seg,) = segments_of(y)
    assert seg[pr.START] == 0.0 and seg[pr.FINISH] == pytest.approx(0.5)
    assert seg[pr.GRAD] == pytest.approx(10.0)
    assert seg[pr.MAX] == pytest.approx(5.0) and seg[pr.MIN] == 0.0  # raw samples (last segment)


def test_a_v_shape_closes_a_segment_and_shares_the_boundary_sample() -> None:
    t = np.arange(201) * 0.005
    y = np.where(t < 0.5, 100 * t, 100 - 100 * t)
    segs = segments_of(y)
    assert len(segs) >= 2
    for a, b in itertools.pairwise(segs):
        assert a[pr.FINISH] == b[pr.START]
    assert segs[0][pr.START] == 0.0 and segs[-1][pr.FINISH] == pytest.approx(1.0)
    assert segs[0][pr.GRAD] > 0  # the failing fit's slope: it already sees the descent
    assert segs[-1][pr.GRAD] == pytest.approx(-100.0, rel=1e-9)


def test_the_gradient_of_a_closed_segment_is_the_failing_fit_slope() -> None:
    """The window that fails includes W samples past the segment's end (spec 2.1)."""
    t = np.arange(41) * 0.005
    y = np.where(t <= 0.1, 0.0, 50 * (t - 0.1))
    seg = segments_of(y)[0]
    end = seg[pr.FINISH]
    n = round(end / 0.005) + 1 + CFG.window
    slope = np.polyfit(t[:n], y[:n], 1)[0]
    assert seg[pr.GRAD] == pytest.approx(slope)


def test_flat_and_tiny_signals() -> None:
    assert len(segments_of(np.full(50, 3.0))) == 1
    assert segments_of(np.array([])) == []
    assert segments_of(np.array([1.0])) == []
    for n in range(2, 6):
        (seg,) = segments_of(np.arange(n, dtype=float))
        assert seg[pr.FINISH] == pytest.approx((n - 1) * 0.005)


def test_block_by_block_feeding_equals_one_batch() -> None:
    rng = np.random.default_rng(3)
    t = np.arange(503) * 0.005
    y = np.cumsum(rng.normal(size=(503, 6)), axis=0)
    batch = pr.segment_arrays(t, y, CFG)
    inc = pr.Segmenter(CFG)
    inc.start(t[0], y[0])
    inc.samples = len(t)
    w = CFG.window
    k = (len(t) - 1) // w
    for j in range(k):
        sl = slice(1 + j * w, 1 + (j + 1) * w)
        inc.feed_blocks(pr.block_stats(t[sl].reshape(1, w), y[sl].reshape(1, w, 6)), 1)
    rest = slice(1 + k * w, len(t))
    n_rest = len(t) - (1 + k * w)
    inc.feed_blocks(
        pr.block_stats(t[rest].reshape(1, n_rest), y[rest].reshape(1, n_rest, 6)), 1, final=True
    )
    assert inc.segments == batch.segments


def test_merge_repeated_primitives_pair_means_and_run_divides_by_k_minus_1() -> None:
    a = prim("cons", 0, 1, 2, 0, avg=1, grad=0.2)
    b = prim("cons", 1, 2, 3, 1, avg=2, grad=0.4)
    c = prim("cons", 2, 3, 5, 2, avg=3, grad=0.6)
    (pair,) = ops.run_ops([pops.RepeatedPrimitives()], [a, b])
    assert pair == [1.5, 3, 0, 0, 2, pytest.approx(0.3), P["cons"]]
    (run,) = ops.run_ops([pops.RepeatedPrimitives()], [a, b, c])
    assert run[pr.AVG] == pytest.approx(6 / 2)  # [bug] sum / (k - 1)
    assert run[pr.GRAD] == pytest.approx(1.2 / 2)
    assert (run[pr.MAX], run[pr.MIN], run[pr.START], run[pr.FINISH]) == (5, 0, 0, 3)


def test_duration_context_merges_short_into_long_with_the_longer_label() -> None:
    long = prim("cons", 0.0, 0.6, 1.0, 0.0)
    short = prim("spos", 0.6, 0.7, 1.5, 0.5)
    (merged,) = durations([long, short])
    assert merged[pr.LABEL] == P["cons"] and merged[pr.FINISH] == 0.7
    (merged,) = durations([short, prim("cons", 0.7, 1.3, 1.5, 0.5)])
    assert merged[pr.LABEL] == P["cons"] and merged[pr.START] == 0.6


@pytest.mark.parametrize(
    ("first", "second"),
    [
        (prim("pimp", 0.0, 0.6), prim("cons", 0.6, 0.7)),  # impulses are never absorbed
        (prim("cons", 0.0, 0.6, 1, 0), prim("spos", 0.6, 0.7, 3, 0)),  # amplitude ratio 3 > 2
        (prim("cons", 0.0, 0.4), prim("spos", 0.4, 0.5)),  # duration ratio 4 < 5
    ],
)
def test_duration_context_keeps_pairs_outside_its_gates(first: list, second: list) -> None:
    assert durations([first, second]) == [first, second]


def test_duration_context_does_not_compare_a_merged_row_again() -> None:
    rows = [prim("cons", 0, 0.6), prim("spos", 0.6, 0.7), prim("sneg", 0.7, 0.72)]
    out = durations(rows)
    assert len(out) == 2 and out[1] == rows[2]


def test_calibration_spectrum() -> None:
    assert pr.gradient_spectrum(10.0, 1.0) == (10.0, 7.0, 4.0, 1.0, -1.0, -4.0, -7.0, -10.0)
    prims = [prim("cons", 0.5, 1.0, grad=4), prim("cons", 1.0, 1.9, grad=2),
             prim("cons", 1.9, 2.1, grad=8), prim("cons", 2.5, 2.9, grad=-20),
             prim("cons", 3.0, 3.5, grad=9)]  # fmt: skip
    pimp, pconst = pr.calibrate_limits(prims, (0.0, 0.6, 2.0, 3.2), "Fx")
    # rotation: start > s2, up to the one before the first whose finish > s3
    assert pconst == pytest.approx(0.9 * 2)
    assert pimp == pytest.approx(0.85 * 20)
    assert pr.calibrate_limits(prims, (0.0, 0.6, 2.0, 3.2), "Fy")[1] == 0.0


# --------------------------------------------------------------------------- MC layer

# (P1, P2) -> (pair label, single label when the ratio gate fails or None, glabel1, glabel2,
# amplitude kind), spelled out from the table of spec 2.2.
TABLE = {
    ("spos", "mpos"): ("i", "i", "spos", "mpos", "span"),
    ("spos", "sneg"): ("a", "i", "spos", "sneg", "range"),
    ("spos", "cons"): ("i", "i", "spos", "cons", "span"),
    ("spos", "pimp"): ("pc", None, "spos", "pimp", "span"),
    ("spos", "nimp"): ("nc", None, "spos", "nimp", "span"),
    ("mneg", "bpos"): ("a", "d", "mneg", "bpos", "span"),
    ("mneg", "sneg"): ("d", "d", "mneg", "sneg", "range"),
    ("mneg", "cons"): ("d", "d", "mneg", "cons", "range"),
    ("mneg", "pimp"): ("pc", None, "mneg", "pimp", "range"),
    ("mneg", "nimp"): ("nc", None, "mneg", "nimp", "range"),
    ("cons", "bpos"): ("i", "k", "cons", "mpos", "span"),
    ("cons", "bneg"): ("d", "k", "cons", "mneg", "range"),
    ("cons", "cons"): ("k", "k", "cons", "cons", "range"),
    ("cons", "pimp"): ("pc", None, "cons", "pimp", "range"),
    ("cons", "nimp"): ("nc", None, "cons", "nimp", "range"),
    ("pimp", "spos"): ("pc", None, "pimp", "mpos", "span"),
    ("pimp", "sneg"): ("c", None, "pimp", "mneg", "range"),
    ("pimp", "cons"): ("pc", None, "pimp", "cons", "span"),
    ("pimp", "pimp"): ("pc", None, "pimp", "mpos", "span"),
    ("pimp", "nimp"): ("c", None, "pimp", "nimp", "range"),
    ("nimp", "bpos"): ("c", None, "nimp", "mpos", "span"),
    ("nimp", "bneg"): ("nc", None, "nimp", "mneg", "range"),
    ("nimp", "cons"): ("nc", None, "nimp", "cons", "range"),
    ("nimp", "pimp"): ("c", None, "nimp", "pimp", "span"),
    ("nimp", "nimp"): ("nc", None, "nimp", "nimp", "range"),
}


@pytest.mark.parametrize(("l1", "l2"), sorted(TABLE))
def test_mc_rule_table_pairs(l1: str, l2: str) -> None:
    label, _, g1, g2, kind = TABLE[(l1, l2)]
    p1 = prim(l1, 0.0, 0.1, vmax=2.0, vmin=1.0, avg=1.5)
    p2 = prim(l2, 0.1, 0.25, vmax=3.0, vmin=1.8, avg=2.4)
    out, paired = mc.match_primitives(p1, p2, CFG)
    assert paired
    amplitude = abs(3.0 - 1.0) if kind == "span" else 3.0 - 1.0
    expected = [M[label], (1.5 + 2.4) / 2, 3.0, amplitude, P[g1], P[g2], 0.0, 0.1, 0.1, 0.25,
                0.125]  # fmt: skip
    assert out == pytest.approx(expected)


def test_mc_amplitude_kinds_differ_when_p2_does_not_reach_p1() -> None:
    p1 = prim("spos", 0.0, 0.1, vmax=5.0, vmin=1.0)
    p2 = prim("spos", 0.1, 0.2, vmax=3.0, vmin=0.0)
    assert mc.match_primitives(p1, p2, CFG)[0][mc.AMP] == pytest.approx(2.0)  # |P2.max - P1.min|
    p2n = prim("sneg", 0.1, 0.2, vmax=3.0, vmin=0.0)
    assert mc.match_primitives(p1, p2n, CFG)[0][mc.AMP] == pytest.approx(5.0)  # max - min


@pytest.mark.parametrize(("l1", "l2"), sorted(k for k, v in TABLE.items() if v[1] is not None))
@pytest.mark.parametrize("gate", ["amplitude", "duration"])
def test_mc_ratio_gate_makes_a_single_mc(l1: str, l2: str, gate: str) -> None:
    single = TABLE[(l1, l2)][1]
    p1 = prim(l1, 0.0, 0.1, vmax=2.0, vmin=1.0)
    p2 = prim(l2, 0.1, 0.2, vmax=4.0, vmin=1.0) if gate == "amplitude" else prim(l2, 0.1, 0.7, 2, 1)
    out, paired = mc.match_primitives(p1, p2, CFG)
    assert not paired
    assert out[mc.LBL] == M[single]
    assert out[mc.GL1] == out[mc.GL2] == P[l1]
    assert out[mc.T1S : mc.TAVG] == [0.0, 0.0, 0.1, 0.1]


def test_mc_scan_consumes_pairs_and_the_last_primitive_pairs_with_itself() -> None:
    prims = [prim("cons", 0, 0.1), prim("cons", 0.1, 0.2), prim("spos", 0.2, 0.3)]
    out = cops.compose(prims, CFG)
    assert [COMPOSITION_LABELS[m[0] - 1] for m in out] == ["k", "i"]
    assert out[1][mc.T1S : mc.TAVG] == [0.2, 0.3, 0.2, 0.3]


# --------------------------------------------------------------------------- MC filtering


def test_similarity_uses_the_signed_max() -> None:
    assert mc.similar(1.0, 1.6, 0.5)
    assert not mc.similar(1.0, 2.1, 0.5)
    assert mc.similar(-1.0, -2.0, 1.0)
    assert not mc.similar(-1.0, -2.5, 1.0)  # |max(-1, -2.5)| = 1, not 2.5


def test_step1_repeated_adjustments_merge_before_mating() -> None:
    rows = [comp("a", 0, 1, avg=1.0, amp=1), comp("a", 1, 2, avg=1.2, amp=3),
            comp("k", 2, 3), comp("k", 3, 4)]  # fmt: skip
    out = run_cycle_op(cops.AdjustmentChains, rows)
    assert len(out) == 3
    a = out[0]
    assert a[mc.LBL] == M["a"] and a[mc.AVGV] == pytest.approx(1.1) and a[mc.AMP] == 3
    assert a[mc.T1E] == pytest.approx(1.0 - 0.002) and a[mc.T2S] == pytest.approx(0.999)
    assert a[mc.T2E] == 2
    # the mating guard: the next MC must end before the limit
    assert len(run_cycle_op(cops.AdjustmentChains, rows, limit=1.5)) == 4
    head = replace(CFG, adjustment_mating_guard=False)
    assert len(run_cycle_op(cops.AdjustmentChains, rows, limit=1.5, config=head)) == 3


def test_step1_needs_two_mcs_after_the_chain() -> None:
    rows = [comp("a", 0, 1), comp("a", 1, 2), comp("k", 2, 3)]
    assert len(run_cycle_op(cops.AdjustmentChains, rows)) == 3


def test_step2_repeated_labels_merge_runs_but_not_adjustments() -> None:
    rows = [comp("i", 0, 1, avg=1, rms=1, amp=5), comp("i", 1, 2, avg=2, rms=4, amp=1),
            comp("i", 2, 3, avg=3, rms=2, amp=1), comp("a", 3, 4), comp("a", 4, 5)]  # fmt: skip
    out = ops.run_ops([cops.RepeatedCompositions()], [list(r) for r in rows])
    assert [r[mc.LBL] for r in out] == [M["i"], M["a"], M["a"]]
    i = out[0]
    assert i[mc.AVGV] == pytest.approx(2.0) and i[mc.RMS] == 4 and i[mc.AMP] == 5
    assert (i[mc.T1S], i[mc.T1E], i[mc.T2S], i[mc.T2E]) == (0, 3, 2, 3)


def test_step3_primitive_duration_relabels_and_the_amplitude_gate_stops_the_pass() -> None:
    rows = [comp("a", 0, 0.7, g1="spos", g2="sneg", t1e=0.6, t2s=0.6, amp=1.0),
            comp("a", 0.7, 1.4, g1="sneg", g2="spos", t1e=0.8, t2s=0.8, amp=1.0)]  # fmt: skip
    op, cycle = cycle_op(cops.PrimitiveDurations)
    out = ops.run_ops([op], [list(r) for r in rows])
    assert [r[mc.LBL] for r in out] == [M["i"], M["a"]]  # the last MC is never examined
    assert cycle.max_amp == 1.0
    rows2 = [comp("k", 0, 1, amp=1.0), comp("a", 1, 2, amp=6.0, g1="spos", t1e=1.9, t2s=1.9),
             comp("k", 2, 3, amp=6.0)]  # fmt: skip
    out = run_cycle_op(cops.PrimitiveDurations, rows2)
    assert out[1][mc.LBL] == M["a"]  # ratio 6 > 5 at the first pair: pass stopped (a1ca1d1)
    head = replace(CFG, duration_gate_breaks=False)
    out = run_cycle_op(cops.PrimitiveDurations, rows2, config=head)
    assert out[1][mc.LBL] == M["i"]  # HEAD skips the pair instead


def test_step4_composition_duration_absorbs_the_short_neighbour() -> None:
    rows = [comp("k", 0, 1.2), comp("i", 1.2, 1.4)]
    (out,) = run_cycle_op(cops.CompositionDurations, rows)
    assert out[mc.LBL] == M["k"] and out[mc.T2E] == 1.4
    rows = [comp("i", 0, 0.1), comp("k", 0.1, 1.3)]
    (out,) = run_cycle_op(cops.CompositionDurations, rows)
    assert out[mc.LBL] == M["k"] and out[mc.T1S] == 0 and out[mc.T2E] == 1.3
    assert out[mc.T1E] == 0.1  # T1E = the first's T2E when merging onto the second


def test_step5_small_contacts_become_increase_or_decrease() -> None:
    rows = [comp("pc", 0, 1, amp=0.5), comp("nc", 1, 2, amp=0.5), comp("pc", 2, 3, amp=2.0)]
    out = run_cycle_op(cops.ContactAmplitudes, rows, max_amp=10.0)
    assert [COMPOSITION_LABELS[r[0] - 1] for r in out] == ["i", "d", "pc"]


@pytest.mark.parametrize(("l1", "l2"), [("a", "i"), ("a", "d"), ("i", "a"), ("d", "a")])
def test_step6_adjustment_pairs(l1: str, l2: str) -> None:
    rows = [comp(l1, 0, 1, amp=1.0, avg=1.0), comp(l2, 1, 2, amp=1.3, avg=1.2)]
    (out,) = pair_pass(mc.ADJUST_PAIRS, (0.5, 0.5), M["a"], rows)
    assert out[mc.LBL] == M["a"] and out[mc.AMP] == 1.3
    rows = [comp(l1, 0, 1, amp=1.0), comp(l2, 1, 2, amp=2.5)]
    assert len(pair_pass(mc.ADJUST_PAIRS, (0.5, 0.5), M["a"], rows)) == 2


@pytest.mark.parametrize(
    ("l1", "l2"), [("i", "k"), ("k", "i"), ("d", "k"), ("k", "d"), ("d", "i"), ("i", "d")]
)
def test_step7_constant_pairs(l1: str, l2: str) -> None:
    rows = [comp(l1, 0, 1, amp=1.0, avg=1.0), comp(l2, 1, 2, amp=2.0, avg=1.9)]
    (out,) = pair_pass(mc.CONSTANT_PAIRS, (1.5, 1.0), M["k"], rows)
    assert out[mc.LBL] == M["k"]


def test_filter_steps_from_start_index_skip_mcs_before_rotation() -> None:
    rows = [comp("a", 0, 1, amp=1.0), comp("i", 1, 2, amp=1.0), comp("k", 2, 3), comp("k", 3, 4)]
    s2, limit = mc.state_limits((0.0, 2.5, 3.0, 3.5), 4.0)
    assert (s2, limit) == (2.5, pytest.approx(3.498))
    ctx = references.whole_context(CFG, (0.0, 2.5, 3.0, 3.5), 4.0)
    out = ops.run_ops(cops.composition_cycle(ctx), [list(r) for r in rows])
    assert [COMPOSITION_LABELS[r[0] - 1] for r in out][:2] == ["a", "i"]


# --------------------------------------------------------------------------- LLB layer


def llbs(rows: list[list]) -> list[tuple[str, str, str]]:
    return [(BEHAVIOR_LABELS[b[0] - 1], COMPOSITION_LABELS[b[bh.B_MC1] - 1],
             COMPOSITION_LABELS[b[bh.B_MC2] - 1]) for b in references.compose_behaviors(rows, CFG)]  # fmt: skip


@pytest.mark.parametrize(
    ("labels", "expected"),
    [
        (["k", "k", "z"], [("FX", "k", "k"), ("N", "z", "n")]),
        (["k", "i", "i"], [("N", "k", "z"), ("PS", "i", "i")]),
        (["d", "d", "c", "c"], [("PL", "d", "d"), ("CT", "c", "c")]),
        (["pc", "nc", "nc", "pc"], [("CT", "pc", "nc"), ("CT", "nc", "pc")]),
        (["pc", "pc", "c"], [("CT", "pc", "z"), ("CT", "pc", "c")]),
        (["i", "k"], [("N", "i", "z"), ("FX", "k", "k")]),
        (["d"], [("PL", "d", "d")]),
        (["c"], [("CT", "c", "c")]),
        (["a"], [("SH", "a", "a")]),
    ],
)
def test_llb_rule_table_on_short_mcs(labels: list[str], expected: list) -> None:
    rows = [comp(lbl, 0.05 * i, 0.05 * (i + 1)) for i, lbl in enumerate(labels)]
    assert llbs(rows) == expected


def test_llb_time_flag_turns_noise_into_singles_and_is_never_reset() -> None:
    rows = [comp("k", 0.0, 0.5), comp("i", 0.5, 0.55), comp("k", 0.55, 0.6), comp("z", 0.6, 0.7)]
    assert llbs(rows) == [("FX", "k", "z"), ("PS", "i", "z"), ("FX", "k", "z"), ("N", "z", "n")]


def test_llb_adjustments_align_or_shift_and_skip_one_mc_when_short() -> None:
    rows = [comp("a", 0, 0.05, amp=2.0), comp("k", 0.05, 0.1), comp("a", 0.1, 0.15, amp=1.0),
            comp("a", 0.15, 0.2, amp=3.0), comp("a", 0.2, 0.25, amp=4.0), comp("k", 0.25, 0.3)]  # fmt: skip
    out = references.compose_behaviors(rows, CFG)
    assert [BEHAVIOR_LABELS[b[0] - 1] for b in out] == ["AL", "SH", "FX"]  # last k: itself
    assert out[0][bh.B_T2S] == 0.1  # paired with the second MC; the k between is dropped
    long = [comp("a", 0, 0.2, amp=2.0), comp("k", 0.2, 0.25), comp("a", 0.25, 0.3, amp=1.0)]
    assert llbs(long)[0] == ("AL", "a", "z")  # longer than 0.1 s: looks at the next MC only


def test_llb_pair_and_single_records() -> None:
    m1 = comp("k", 0.0, 0.2, amp=1.0, avg=2.0, rms=3.0)
    m2 = comp("k", 0.2, 0.3, amp=4.0, avg=1.0, rms=1.0)
    (pair,) = references.compose_behaviors([m1, m2], CFG)
    assert pair[1:10] == [2.0, 1.0, 1.5, 3.0, 1.0, 3.0, 1.0, 4.0, 4.0]
    assert pair[bh.B_T1S :] == [0.0, 0.2, 0.2, 0.3, pytest.approx((0.1 + 0.25) / 2)]
    single = references.compose_behaviors(
        [comp("pc", 0, 0.1, t1e=0.0, t2s=0.1), comp("k", 0.1, 0.2)], CFG
    )[0]
    assert single[bh.B_T1S :] == [0.0, 0.0, 0.1, 0.1, 0.05]


# --------------------------------------------------------------------------- LLB refinement


def test_refinement_duration_context_merges_a_prefix_then_stops() -> None:
    rows = [beh("FX", 0, 6, mc2="k"), beh("PS", 6, 7, mc2="i"),
            beh("PL", 7, 8, mc2="d"), beh("FX", 8, 30, mc2="k"), beh("FX", 30, 31, mc2="k")]  # fmt: skip
    out = ops.run_ops([bops.BehaviorDurations(CFG)], [list(r) for r in rows])
    assert [BEHAVIOR_LABELS[r[0] - 1] for r in out] == ["FX", "PL", "FX", "FX"]
    assert out[0][bh.B_T2E] == 7
    assert COMPOSITION_LABELS[out[0][bh.B_MC1] - 1] == "a"  # FX = 1 printed through the MC table


def test_refinement_duration_context_skips_singles_and_stops_on_large_amplitude() -> None:
    rows = [beh("FX", 0, 6, mc2="z"), beh("PS", 6, 7), beh("PL", 7, 8)]
    assert len(ops.run_ops([bops.BehaviorDurations(CFG)], [list(r) for r in rows])) == 3
    rows = [beh("FX", 0, 6, amp=1.0), beh("PS", 6, 7, amp=6.0), beh("PL", 7, 8)]
    assert len(ops.run_ops([bops.BehaviorDurations(CFG)], [list(r) for r in rows])) == 3


def test_refinement_merge_onto_the_longer_second_keeps_its_label() -> None:
    rows = [beh("PS", 0, 1), beh("FX", 1, 7), beh("PL", 7, 8)]
    out = ops.run_ops([bops.BehaviorDurations(CFG)], [list(r) for r in rows])
    assert BEHAVIOR_LABELS[out[0][0] - 1] == "FX"
    assert (out[0][bh.B_T1S], out[0][bh.B_T2E]) == (0, 7)


@pytest.mark.parametrize(
    ("pair", "expected"),
    [
        (("PS", "PL"), "AL"),  # step 2: every PS/PL pair (amplitude tested twice [bug])
        (("PL", "PS"), "AL"),
        (("SH", "AL"), "AL"),  # step 3 (second amplitude smaller)
        (("AL", "AL"), "AL"),
        (("FX", "FX"), "FX"),  # step 4: repeats
        (("CT", "CT"), "CT"),
        (("AL", "PS"), "AL"),  # step 5
        (("SH", "PL"), "AL"),
        (("PS", "FX"), "FX"),  # step 6
        (("FX", "SH"), "FX"),
    ],
)
def test_refinement_amplitude_context_merges(pair: tuple[str, str], expected: str) -> None:
    rows = [
        beh(pair[0], 0, 1, amp=1.0, mag=1.0, mc2="z"),
        beh(pair[1], 1, 2, amp=0.9, mag=1.0, mc2="z"),
    ]
    (out,) = ops.run_ops(bops.refinement_cycle(CFG), [list(r) for r in rows])
    assert BEHAVIOR_LABELS[out[0] - 1] == expected
    assert (out[bh.B_T1S], out[bh.B_T2E]) == (0, 2)


@pytest.mark.parametrize(
    ("first", "second"), [("PS", "AL"), ("PL", "SH"), ("SH", "AL"), ("CT", "FX")]
)
def test_refinement_leaves_other_pairs(first: str, second: str) -> None:
    rows = [beh(first, 0, 1, amp=1.0, mc2="z"), beh(second, 1, 2, amp=1.5, mc2="z")]
    assert len(ops.run_ops(bops.refinement_cycle(CFG), [list(r) for r in rows])) == 2


def test_ieee_division() -> None:
    assert pr.ieee_div(1.0, 0.0) == math.inf
    assert math.isnan(pr.ieee_div(0.0, 0.0))
    assert pr.ieee_div(-1.0, 0.0) == -math.inf


def test_a_one_sample_segment_gets_the_twentieth_rule() -> None:
    """First window closed, the next one fails at once: segment i..i, dFinish += dFinish/20."""
    y = np.array([(-1.0) ** k for k in range(40)])
    segs = segments_of(y)
    assert segs[0][pr.START] == 0.0 and segs[0][pr.FINISH] == pytest.approx(0.025)
    assert segs[1][pr.START] == pytest.approx(0.025)
    assert segs[1][pr.FINISH] == pytest.approx(0.025 + 0.025 / 20)

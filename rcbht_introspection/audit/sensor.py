"""The sensor's side of the audit: frozen stretches, dropped stamps, gaps, the sampling rate of
each trial against the others, and trials that end before their task does."""

from __future__ import annotations

from typing import Any

import numpy as np

from rcbht_introspection.audit.facts import TrialFacts
from rcbht_introspection.audit.findings import Finding, seconds

RATE_TOLERANCE = 0.01
"""A trial's rate must also differ from the set's median by more than this share to be
reported (below it the taxonomy's windows change by less than 1 %)."""
LISTED = 6
"""Trials named in a message (all are in the finding's trials)."""


def _listed(parts: list[str]) -> str:
    more = f" and {len(parts) - LISTED} more" if len(parts) > LISTED else ""
    return ", ".join(parts[:LISTED]) + more


def frozen_finding(facts: list[TrialFacts]) -> list[Finding]:
    hit = [f for f in facts if f.frozen]
    if not hit:
        return []
    rows: list[dict[str, Any]] = [
        {
            "trial": f.name,
            "arm": s.arm,
            "t0": s.t0,
            "t1": s.t1,
            "samples": s.samples,
            "share": s.samples / max(f.timing.samples, 1),
        }
        for f in hit
        for s in f.frozen
    ]
    longest = max(rows, key=lambda r: r["t1"] - r["t0"])
    parts = [
        f"{f.name} ({len(f.frozen)} run(s), {sum(s.samples for s in f.frozen)} samples)"
        for f in hit
    ]
    message = (
        f"frozen sensor (the same six values over many samples) in {len(hit)} trial(s): "
        f"{_listed(parts)}; longest {longest['t1'] - longest['t0']:.2f} s in {longest['trial']}"
    )
    strength = {
        "runs": len(rows),
        "longest_s": longest["t1"] - longest["t0"],
        "samples": sum(int(r["samples"]) for r in rows),
    }
    names = tuple(f.name for f in hit)
    return [Finding("frozen_sensor", message, names, (), None, strength, {"runs": rows})]


def dropped_finding(facts: list[TrialFacts]) -> list[Finding]:
    hit = [f for f in facts if f.dropped]
    if not hit:
        return []
    total: dict[str, int] = {}
    for f in hit:
        for key, n in f.dropped.items():
            total[key] = total.get(key, 0) + n
    messages = sum(f.messages or 0 for f in hit)
    counts = ", ".join(f"{n} {key}" for key, n in sorted(total.items()))
    share = sum(total.values()) / messages if messages else None
    of = f" ({100 * share:.1f} % of {messages} messages)" if share is not None else ""
    message = (
        f"samples dropped or moved for their stamps in {len(hit)} of {len(facts)} trial(s): "
        f"{counts}{of}"
    )
    rows = [{"trial": f.name, **f.dropped, "messages": f.messages} for f in hit]
    strength: dict[str, object] = {"counts": total, "share_of_messages": share}
    names = tuple(f.name for f in hit)
    return [Finding("dropped_stamps", message, names, (), None, strength, {"trials": rows})]


def gap_finding(facts: list[TrialFacts]) -> list[Finding]:
    hit = [f for f in facts if f.timing.gaps]
    if not hit:
        return []
    worst = max(hit, key=lambda f: f.timing.longest_gap_s)
    parts = [f"{f.name} ({f.timing.gaps}, longest {seconds(f.timing.longest_gap_s)})" for f in hit]
    step = worst.timing.period_s[1]
    ratio = worst.timing.longest_gap_s / step if step > 0 else float("inf")
    message = (
        f"gaps in the samples (steps beyond the far-out fence of the trial's own steps) in "
        f"{len(hit)} trial(s): {_listed(parts)}; the longest is {ratio:.1f} median steps"
    )
    strength = {
        "gaps": sum(f.timing.gaps for f in hit),
        "longest_s": worst.timing.longest_gap_s,
        "longest_in_median_steps": ratio,
        "missing_s": sum(f.timing.missing_s for f in hit),
    }
    rows = [
        {
            "trial": f.name,
            "gaps": f.timing.gaps,
            "longest_s": f.timing.longest_gap_s,
            "fence_s": f.timing.gap_fence_s,
            "missing_s": f.timing.missing_s,
        }
        for f in hit
    ]
    return [
        Finding("gaps", message, tuple(f.name for f in hit), (), None, strength, {"trials": rows})
    ]


def rate_finding(facts: list[TrialFacts]) -> list[Finding]:
    """Trials whose rate lies beyond Tukey's far-out fences of the set's rates (and differs from
    their median by more than RATE_TOLERANCE)."""
    rates = np.array([f.timing.rate_hz for f in facts if f.timing.rate_hz > 0])
    if len(rates) < 2:
        return []
    q1, median, q3 = np.percentile(rates, [25, 50, 75])
    low, high = q1 - 3 * (q3 - q1), q3 + 3 * (q3 - q1)
    odd = [
        f
        for f in facts
        if f.timing.rate_hz > 0
        and not low <= f.timing.rate_hz <= high
        and abs(f.timing.rate_hz / median - 1) > RATE_TOLERANCE
    ]
    if not odd:
        return []
    parts = [f"{f.name} {f.timing.rate_hz:.4g} Hz" for f in odd]
    message = (
        f"sampling rate differs from the set's ({median:.4g} Hz, quartiles {q1:.4g}-{q3:.4g}) in "
        f"{len(odd)} trial(s): {_listed(parts)}"
    )
    worst = max(odd, key=lambda f: abs(f.timing.rate_hz / median - 1))
    strength = {
        "median_hz": float(median),
        "fences_hz": [float(low), float(high)],
        "largest_relative_difference": float(worst.timing.rate_hz / median - 1),
    }
    rows = [{"trial": f.name, "rate_hz": f.timing.rate_hz} for f in odd]
    return [
        Finding(
            "sampling_rate",
            message,
            tuple(f.name for f in odd),
            (),
            None,
            strength,
            {"trials": rows},
        )
    ]


def incomplete_finding(facts: list[TrialFacts]) -> list[Finding]:
    hit = [f for f in facts if f.cut is not None]
    if not hit:
        return []
    parts = [f"{f.name} (ends in {f.cut})" for f in hit]
    message = f"{len(hit)} trial(s) end before their task does: {_listed(parts)}"
    subtasks = tuple(sorted({str(f.cut) for f in hit}))
    return [
        Finding(
            "incomplete_trial",
            message,
            tuple(f.name for f in hit),
            subtasks,
            None,
            {"trials": len(hit)},
            {"cut": {f.name: f.cut for f in hit}},
        )
    ]


def states_finding(facts: list[TrialFacts]) -> list[Finding]:
    hit = [f for f in facts if f.dropped_states]
    if not hit:
        return []
    reasons: dict[str, int] = {}
    for f in hit:
        for d in f.dropped_states:
            reasons[str(d.get("reason"))] = reasons.get(str(d.get("reason")), 0) + 1
    counts = ", ".join(f"{n} {reason}" for reason, n in sorted(reasons.items()))
    parts = [f"{f.name} ({len(f.dropped_states)})" for f in hit]
    message = (
        f"state times dropped when read ({counts}) in {len(hit)} of {len(facts)} trial(s): "
        f"{_listed(parts)}"
    )
    rows = {f.name: list(f.dropped_states) for f in hit}
    strength = {"state_times": sum(reasons.values()), "reasons": reasons}
    names = tuple(f.name for f in hit)
    return [Finding("dropped_state_times", message, names, (), None, strength, {"trials": rows})]


def unreadable_finding(unreadable: list[tuple[str, str]]) -> list[Finding]:
    if not unreadable:
        return []
    message = f"{len(unreadable)} input(s) could not be read: " + "; ".join(
        error for _, error in unreadable[:3]
    )
    rows = [{"path": path, "error": error} for path, error in unreadable]
    return [
        Finding(
            "unreadable",
            message,
            tuple(p for p, _ in unreadable),
            (),
            None,
            {"inputs": len(unreadable)},
            {"inputs": rows},
        )
    ]


def sensor_findings(facts: list[TrialFacts], unreadable: list[tuple[str, str]]) -> list[Finding]:
    """Every sensor and completeness finding of the set."""
    return [
        *unreadable_finding(unreadable),
        *states_finding(facts),
        *incomplete_finding(facts),
        *frozen_finding(facts),
        *gap_finding(facts),
        *dropped_finding(facts),
        *rate_finding(facts),
    ]

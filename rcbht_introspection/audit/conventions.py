"""Findings of the sub-task durations: convention changes, duration shifts and outliers, each
change with the classifier check of audit/agreement.py beside it."""

from __future__ import annotations

import dataclasses
import itertools
from typing import Any

from rcbht_introspection.audit.agreement import Agreement, cross_agreement
from rcbht_introspection.audit.durations import DurationChange, SubtaskDurations, between
from rcbht_introspection.audit.facts import TrialFacts
from rcbht_introspection.audit.findings import Finding, seconds, sigmas, span
from rcbht_introspection.audit.settings import AuditSettings

Pair = tuple[SubtaskDurations, DurationChange, SubtaskDurations, DurationChange]


def convention_pairs(results: list[SubtaskDurations]) -> list[Pair]:
    """Neighbouring sub-tasks that change at the same trial in opposite directions."""
    pairs = []
    for a, b in itertools.pairwise(results):
        for ca in a.changes:
            for cb in b.changes:
                if between(a, ca) == between(b, cb) and ca.shift_sigmas * cb.shift_sigmas < 0:
                    pairs.append((a, ca, b, cb))
    return pairs


def change_strength(c: DurationChange) -> dict[str, float]:
    return {
        "z": round(c.change.statistic, 4),
        "p": c.change.p_value,
        "p_bonferroni": c.change.p_adjusted,
        "shift_sigmas": round(c.shift_sigmas, 2),
        "median_before_s": c.before.median_s,
        "median_after_s": c.after.median_s,
    }


def statistic_note(settings: AuditSettings, tests: int) -> dict[str, object]:
    return {
        "statistic": "rank changepoint z (largest standardised Mann-Whitney sum over splits) of "
        "the log durations; shift in robust sigmas of the log durations",
        "permutations": settings.permutations,
        "bonferroni_tests": tests,
        "alpha": settings.alpha,
    }


def sides(r: SubtaskDurations, c: DurationChange) -> dict[str, list[str]]:
    """First and last trial of the two sides of a change."""
    return {
        "before": [r.trials[c.before.start], r.trials[c.before.stop - 1]],
        "after": [r.trials[c.after.start], r.trials[c.after.stop - 1]],
    }


def convention_finding(pair: Pair, settings: AuditSettings, tests: int) -> Finding:
    a, ca, b, cb = pair
    before, after = between(a, ca)
    message = (
        f"labelling convention changes between {before} and {after}: the {a.subtask}|"
        f"{b.subtask} boundary moved; {a.subtask} {seconds(ca.before.median_s)} -> "
        f"{seconds(ca.after.median_s)} ({sigmas(ca.shift_sigmas)}), {b.subtask} "
        f"{seconds(cb.before.median_s)} -> {seconds(cb.after.median_s)} "
        f"({sigmas(cb.shift_sigmas)}); z {ca.change.statistic:.2f} and {cb.change.statistic:.2f}, "
        f"p {ca.change.p_adjusted:.2g} and {cb.change.p_adjusted:.2g} (Bonferroni x{tests}, "
        f"{settings.permutations} permutations)"
    )
    strength = {
        **statistic_note(settings, tests),
        a.subtask: change_strength(ca),
        b.subtask: change_strength(cb),
    }
    where = (before, after)
    return Finding(
        "convention_change",
        message,
        where,
        (a.subtask, b.subtask),
        where,
        strength,
        {**sides(a, ca), "rows": _rows(a, ca)},
    )


def shift_finding(
    r: SubtaskDurations, c: DurationChange, settings: AuditSettings, tests: int
) -> Finding:
    before, after = between(r, c)
    message = (
        f"{r.subtask} changes length between {before} and {after}: "
        f"{seconds(c.before.median_s)} -> {seconds(c.after.median_s)} ({sigmas(c.shift_sigmas)}), "
        f"z {c.change.statistic:.2f}, p {c.change.p_adjusted:.2g} (Bonferroni x{tests}); no "
        "neighbouring sub-task changes the other way there"
    )
    strength = {**statistic_note(settings, tests), **change_strength(c)}
    where = (before, after)
    return Finding(
        "duration_shift",
        message,
        where,
        (r.subtask,),
        where,
        strength,
        {**sides(r, c), "rows": _rows(r, c)},
    )


def _rows(r: SubtaskDurations, c: DurationChange) -> list[int]:
    """Positions among all trials of the first before, the first after and the last after."""
    return [r.rows[c.before.start], r.rows[c.after.start], r.rows[c.after.stop - 1]]


def outlier_finding(r: SubtaskDurations, settings: AuditSettings) -> list[Finding]:
    """One finding per sub-task with outlying durations."""
    if not r.outliers:
        return []
    part_of = {i: p for p in r.parts for i in range(p.start, p.stop)}
    rows: list[dict[str, Any]] = [
        {
            "trial": r.trials[i],
            "seconds": r.seconds[i],
            "part_median_s": part_of[i].median_s,
            "z": round(z, 2),
            "p_bonferroni": p,
        }
        for i, z, p in r.outliers
    ]
    listed = ", ".join(
        f"{row['trial']} {seconds(row['seconds'])} (z {row['z']:+.1f})" for row in rows[:6]
    )
    more = f" and {len(rows) - 6} more" if len(rows) > 6 else ""
    message = (
        f"{r.subtask}: {len(rows)} outlying duration(s) against the median of their part: "
        f"{listed}{more}"
    )
    strength = {
        "statistic": "robust z of the log duration (median and robust sigma of its part), "
        "two-sided normal p, Bonferroni over every duration",
        "largest_abs_z": max(abs(float(row["z"])) for row in rows),
        "alpha": settings.alpha,
    }
    names = tuple(str(row["trial"]) for row in rows)
    return [
        Finding("duration_outlier", message, names, (r.subtask,), None, strength, {"rows": rows})
    ]


def describe_agreement(found: Finding, agreement: Agreement) -> str:
    """What each side's model calls the other side's time of the finding's sub-tasks: every
    sub-task it mostly calls by another name, else that the models agree with the labels."""
    before, after = span(found.detail["before"]), span(found.detail["after"])
    renamed = []
    agreeing = []
    for name in found.subtasks:
        for called, model, other in (
            (agreement.after_by_before, before, after),
            (agreement.before_by_after, after, before),
        ):
            shares = called.get(name)
            if not shares:
                continue
            top, share = next(iter(shares.items()))
            if top == name:
                agreeing.append(share)
            else:
                renamed.append(
                    f"the model of {model} calls {100 * share:.0f} % of {other}'s "
                    f"{name} time {top!r}"
                )
    if renamed:
        return "classifier check: " + "; ".join(renamed)
    if agreeing:
        low, high = f"{100 * min(agreeing):.0f}", f"{100 * max(agreeing):.0f}"
        agreed = low if low == high else f"{low}-{high}"
        return (
            f"classifier check: each side's model gives the other side's {', '.join(found.subtasks)} "
            f"time its own label ({agreed} %)"
        )
    return ""


def with_agreement(
    found: Finding,
    facts: list[TrialFacts],
    cache: dict[tuple[int, ...], Agreement | None],
    seed: int,
) -> Finding:
    """The finding with the classifier check of its change (computed once per change)."""
    first, split, last = found.detail["rows"]
    key = (first, split, last)
    if key not in cache:
        windows: list[Any] = [(f.windows, f.window_labels) for f in facts[first : last + 1]]
        if any(w is None for w, _ in windows):
            cache[key] = None
        else:
            cache[key] = cross_agreement(windows[: split - first], windows[split - first :], seed)
    agreement = cache[key]
    detail = {k: v for k, v in found.detail.items() if k != "rows"}
    if agreement is None:
        return dataclasses.replace(found, detail=detail)
    return dataclasses.replace(
        found,
        evidence=describe_agreement(found, agreement),
        detail={**detail, "classifier": agreement.to_dict()},
    )


def duration_findings(
    results: list[SubtaskDurations], facts: list[TrialFacts], settings: AuditSettings
) -> list[Finding]:
    """Convention changes, duration shifts and outliers of the durations, as findings."""
    tests = sum(1 for r in results if len(r.trials) >= 2 * settings.min_segment)
    pairs = convention_pairs(results)
    used = {id(c) for _, ca, _, cb in pairs for c in (ca, cb)}
    changes = [convention_finding(p, settings, tests) for p in pairs]
    changes += [
        shift_finding(r, c, settings, tests)
        for r in results
        for c in r.changes
        if id(c) not in used
    ]
    cache: dict[tuple[int, ...], Agreement | None] = {}
    changes = [with_agreement(f, facts, cache, settings.seed) for f in changes]
    return changes + [f for r in results for f in outlier_finding(r, settings)]

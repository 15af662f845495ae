"""Audit a data set: read every trial once, reduce it to its facts, find what is wrong, and
write the report (text and JSON, docs/audit.md)."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rcbht_introspection.audit.conventions import duration_findings
from rcbht_introspection.audit.durations import SubtaskDurations, analyse_durations, durations_dict
from rcbht_introspection.audit.facts import TrialFacts, trial_facts
from rcbht_introspection.audit.findings import ACTIONS, Finding
from rcbht_introspection.audit.sensor import sensor_findings
from rcbht_introspection.audit.sessions import (
    GAP_SIGMAS,
    Sessions,
    analyse_sessions,
    session_findings,
    sessions_dict,
)
from rcbht_introspection.audit.settings import AuditSettings, check_settings
from rcbht_introspection.errors import InputError
from rcbht_introspection.fleet import Failed, attempt, parallel_map
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.task import Task, task_of_names

FORMAT = "rcbht-audit"
FORMAT_VERSION = 1
KINDS: tuple[str, ...] = tuple(ACTIONS)


@dataclass
class AuditReport:
    """What the audit found in a data set."""

    task: Task
    settings: AuditSettings
    facts: list[TrialFacts]
    durations: list[SubtaskDurations]
    sessions: Sessions
    findings: list[Finding]
    inputs: list[str] = field(default_factory=list)
    unreadable: list[tuple[str, str]] = field(default_factory=list)

    def of_kind(self, kind: str) -> list[Finding]:
        return [f for f in self.findings if f.kind == kind]


def set_task(facts: Sequence[TrialFacts], tasks: Sequence[Task]) -> Task:
    """The one task of the trials, else the task of all their phase sequences."""
    if tasks and all(t == tasks[0] for t in tasks):
        return tasks[0]
    return task_of_names([f.phases for f in facts])


def audit_facts(
    facts: list[TrialFacts],
    task: Task,
    settings: AuditSettings,
    inputs: Sequence[str] = (),
    unreadable: Sequence[tuple[str, str]] = (),
) -> AuditReport:
    """The audit of trials already reduced to their facts (in trial order)."""
    check_settings(settings)
    periods = [f.timing.period_s[1] for f in facts if f.timing.samples > 1]
    settings = dataclasses.replace(
        settings, period_s=float(np.median(periods)) if periods else settings.period_s
    )
    durations = analyse_durations(facts, task, settings)
    sessions = analyse_sessions(facts, settings)
    findings = [
        *duration_findings(durations, facts, settings),
        *session_findings(sessions, settings),
        *sensor_findings(facts, list(unreadable)),
    ]
    findings.sort(key=lambda f: KINDS.index(f.kind))
    return AuditReport(
        task, settings, facts, durations, sessions, findings, list(inputs), list(unreadable)
    )


def audit_trials(
    trials: Iterable[Trial], settings: AuditSettings | None = None, task: Task | None = None
) -> AuditReport:
    """The audit of Trial objects in the order given (`task`: default, their phase names')."""
    settings = settings or AuditSettings()
    trials = list(trials)
    task = task or task_of_names([t.phase_names for t in trials])
    facts = [
        trial_facts(
            t, t.name, task, settings.frozen_samples, settings.frozen_s, settings.classifier
        )
        for t in trials
    ]
    return audit_facts(facts, task, settings)


def _read_facts(settings: AuditSettings, path: Path) -> tuple[TrialFacts, Task]:
    """One input read and reduced to its facts, with its task (on any worker)."""
    from rcbht_introspection.learn.data import read_any_trial, task_of_bag
    from rcbht_introspection.task import task_of_folder

    trial = read_any_trial(path, settings.repeated)
    task = task_of_bag(trial) if path.is_file() else task_of_folder(path)
    facts = trial_facts(
        trial, path, task, settings.frozen_samples, settings.frozen_s, settings.classifier
    )
    return facts, task


def audit_paths(
    inputs: Sequence[Path | str], settings: AuditSettings | None = None, jobs: int = 1
) -> AuditReport:
    """The audit of trial folders, dataset folders and trial bags, in the order the other
    commands take them (learn/data.find_inputs: each folder sorted by name), read on `jobs`
    joblib workers (fleet.parallel_map; the report is the same whatever N). A trial that cannot
    be read is counted (finding 'unreadable') and the others are audited; none readable is an
    InputError."""
    from rcbht_introspection.learn.data import find_inputs

    settings = settings or AuditSettings()
    check_settings(settings)
    read = functools.partial(attempt, functools.partial(_read_facts, settings))
    outcomes = parallel_map(read, find_inputs(inputs), jobs)
    unreadable = [(o.input, o.reason) for o in outcomes if isinstance(o, Failed)]
    done = [o for o in outcomes if not isinstance(o, Failed)]
    facts, tasks = [f for f, _ in done], [t for _, t in done]
    if not facts:
        first = unreadable[0][1] if unreadable else "no trials"
        raise InputError(f"no trial could be read ({len(unreadable)} tried); first: {first}")
    return audit_facts(
        facts, set_task(facts, tasks), settings, [str(p) for p in inputs], unreadable
    )


def trial_dict(f: TrialFacts) -> dict[str, Any]:
    t = f.timing
    return {
        "name": f.name,
        "path": f.path,
        "phases": list(f.phases),
        "durations_s": {name: round(d, 6) for name, d in f.durations.items()},
        "cut": f.cut,
        "samples": t.samples,
        "rate_hz": t.rate_hz,
        "period_s": {"q1": t.period_s[0], "median": t.period_s[1], "q3": t.period_s[2]},
        "gaps": {
            "count": t.gaps,
            "longest_s": t.longest_gap_s,
            "missing_s": t.missing_s,
            "fence_s": t.gap_fence_s,
        },
        "frozen": [dataclasses.asdict(s) for s in f.frozen],
        "dropped": f.dropped,
        "dropped_state_times": list(f.dropped_states),
        "level": {arm: list(v) for arm, v in f.level.items()},
    }


def report_dict(report: AuditReport) -> dict[str, Any]:
    """The JSON report (docs/audit.md)."""
    rates = [f.timing.rate_hz for f in report.facts if f.timing.rate_hz > 0]
    counts = {kind: len(report.of_kind(kind)) for kind in KINDS}
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "inputs": report.inputs,
        "settings": report.settings.to_dict(),
        "task": report.task.to_dict(),
        "trials": [trial_dict(f) for f in report.facts],
        "rate_hz": {"median": float(np.median(rates)), "min": min(rates), "max": max(rates)}
        if rates
        else None,
        "durations": durations_dict(report.durations),
        "sessions": sessions_dict(report.sessions),
        "findings": [f.to_dict() for f in report.findings],
        "notes": notes(report),
        "bad_inputs": {
            "count": len(report.unreadable),
            "of": len(report.facts) + len(report.unreadable),
            "inputs": [{"input": i, "reason": r} for i, r in report.unreadable],
        },
        "summary": counts,
    }


def whole_set_lines(report: AuditReport) -> list[str]:
    """The test of every whole sequence, significant or not (how far from a change each is)."""
    tested = [(r.subtask, r.whole) for r in report.durations if r.whole is not None]
    durations = ", ".join(f"{name} z {w.statistic:.2f} p {w.p_adjusted:.2g}" for name, w in tested)
    sessions = report.sessions
    sizes = "+".join(str(len(g)) for g in sessions.groups)
    whole = sessions.whole
    level = f"z {whole.statistic:.2f} p {whole.p_value:.2g}" if whole else "too few trials"
    return [
        f"changepoint test of all trials, durations (Bonferroni x{len(tested)}): "
        + (durations or "too few trials"),
        f"sessions by free-motion level (gaps beyond {GAP_SIGMAS:g} sigma): "
        f"{len(sessions.groups)} ({sizes} trials); changepoint test of the largest in input "
        f"order: {level}; level changes within sessions: {len(sessions.changes)}",
    ]


def notes(report: AuditReport) -> list[str]:
    """What limits the audit itself: permutations too few for any change to be significant."""
    tested = sum(1 for r in report.durations if r.whole is not None)
    smallest = max(tested, 1) / (1 + report.settings.permutations)
    if smallest > report.settings.alpha:
        return [
            f"with {report.settings.permutations} permutations the smallest p-value after "
            f"Bonferroni x{tested} is {smallest:.2g}, above alpha {report.settings.alpha}: no "
            "change of the durations can be found; give more --permutations"
        ]
    return []


def report_text(report: AuditReport) -> list[str]:
    """The lines `rcbht audit` prints: the set, every finding with what to do, and a summary."""
    facts = report.facts
    rates = [f.timing.rate_hz for f in facts if f.timing.rate_hz > 0]
    rate = f"{np.median(rates):.4g} Hz ({min(rates):.4g}-{max(rates):.4g})" if rates else "no rate"
    medians = ", ".join(
        f"{r.subtask} {np.median(r.seconds):.3g} s" for r in report.durations if r.seconds
    )
    lines = [
        f"{len(facts)} trial(s), {len(report.unreadable)} unreadable; sub-tasks "
        f"{' > '.join(report.task.subtasks)}; {rate}",
        f"median durations: {medians}",
        *whole_set_lines(report),
        *(f"note: {note}" for note in notes(report)),
    ]
    for f in report.findings:
        lines.append(f"[{f.kind}] {f.message}")
        if f.evidence:
            lines.append(f"    evidence: {f.evidence}")
        lines.append(f"    do: {f.action}")
    conventions = report.of_kind("convention_change")
    named = "; ".join(
        f"{'|'.join(f.subtasks)} between {' and '.join(f.between or ())}" for f in conventions
    )
    lines.append(
        f"convention changes: {len(conventions)} ({named})" if named else "convention changes: none"
    )
    lines.append(f"findings: {len(report.findings)}")
    return lines

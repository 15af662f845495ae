"""Scores of the verifier in a replay: what verifier_node published per bag, against the labels
and against the offline verifier on the same trial (no ROS).

The rules are verify/evaluate.py's (`metrics`): an alarm is a true positive only within
GATE_S after the labelled onset (before it: a false alarm), any alarm on a nominal run is a
false positive. The onset is the trial's label (metadata["failure"]["onset"]) or, without one,
the start of its first failing sub-task (verify/train.onset_for), stated per run.
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rcbht_introspection.io.trial import Trial
from rcbht_introspection.verify.evaluate import GATE_S, RunResult, metrics
from rcbht_introspection.verify.features import trial_features
from rcbht_introspection.verify.labels import TrialLabel, label_of
from rcbht_introspection.verify.mismatch import MISMATCH
from rcbht_introspection.verify.model_file import VerifierModel
from rcbht_introspection.verify.stream import offline_verdicts
from rcbht_introspection.verify.train import onset_for


@dataclass
class VerdictRecord:
    """What verifier_node published for one bag (one stream)."""

    stream_id: int
    verdicts: int = 0
    max_score: float = 0.0
    alarm_time: float | None = None
    alarm_health: str = ""
    """/task_health's value carried by the alarm's verdict (anomaly or the class then)."""
    alarm_signal: str = ""
    """The signal furthest over its threshold at the alarm's verdict."""
    onset_estimate: float | None = None
    final_class: str = ""
    """The class of the stream's last verdict (the most evidence)."""
    directions: dict[str, str] = field(default_factory=dict)
    end_time: float = 0.0
    """Stream time of the last verdict received."""
    health_seen: list[str] = field(default_factory=list)
    """Distinct /task_health values received while the bag played, in order."""
    arrivals: list[tuple[int, int]] = field(default_factory=list)
    """(wall ns received, tick stamp ns) of each verdict"""
    latencies_ns: list[int] = field(default_factory=list)
    """Sample -> verdict latency of each verdict (verdict_latencies)"""

    def add(
        self,
        time: float,
        score: float,
        alarm_time: float | None,
        onset: float | None,
        failure_class: str,
        directions: dict[str, str],
        health: str,
        signal: str = "",
    ) -> None:
        """One Verdict message of this stream (`signal`: its signal furthest over threshold)."""
        self.verdicts += 1
        self.max_score = max(self.max_score, score)
        if alarm_time is not None and self.alarm_time is None:
            self.alarm_time, self.onset_estimate, self.alarm_health = alarm_time, onset, health
            self.alarm_signal = signal
        if alarm_time is not None:
            self.final_class, self.directions = failure_class, dict(directions)
        self.end_time = max(self.end_time, time)


def verdict_latencies(
    pub_series: Sequence[tuple[int, int]], arrivals: Sequence[tuple[int, int]]
) -> list[int]:
    """Sample -> verdict latencies (ns): from the publication of the first wrench sample stamped
    after a verdict's tick (the earliest the tick can be judged) to the verdict's arrival here.
    `pub_series`: (wall ns, stamp ns) of each published stamp, in order. The last verdict of a
    stream (at the end event, no later sample) has none."""
    stamps = [stamp for _, stamp in pub_series]
    out = []
    for wall, tick in arrivals:
        i = bisect.bisect_right(stamps, tick)
        if i < len(stamps):
            out.append(wall - pub_series[i][0])
    return out


def _outcome(r: RunResult, gate_s: float) -> str:
    if not r.label.failed:
        return "false alarm" if r.alarm is not None else "nominal"
    if r.alarm is None or r.onset is None:
        return "missed"
    if r.alarm < r.onset:
        return "early alarm"
    return "detected" if r.alarm <= r.onset + gate_s else "late"


def _true_onset(trial: Trial, label: TrialLabel, model: VerifierModel) -> tuple[float | None, str]:
    """A failed trial's onset and where it comes from: its label, else the model's timing
    estimate from the trial's features; none for a success."""
    if not label.failed:
        return None, ""
    if label.onset is not None:
        return label.onset, "label"
    timing = model.detector.models.timing
    if timing is None:
        return None, ""
    return onset_for(label, trial_features(trial, model.config), timing)


def _run_result(
    rec: VerdictRecord, trial: Trial, label: TrialLabel, onset: float | None, source: str
) -> RunResult:
    """The node's run in the offline protocol's form (no score series: not observed)."""
    return RunResult(
        trial=trial.name,
        label=label,
        onset=onset,
        onset_source=source,
        run_score=rec.max_score,
        alarm=rec.alarm_time,
        alarm_signal="",
        onset_estimate=rec.onset_estimate,
        predicted_class=rec.final_class,
        class_by_evidence={},
        class_given_onset="",
        directions=rec.directions,
        directions_given_onset={},
        times=np.zeros(0),
        score=np.zeros(0),
        classes_over_time=[],
    )


def _offline_match(rec: VerdictRecord, trial: Trial, model: VerifierModel) -> dict[str, Any]:
    """The offline verifier's alarm and class on the same trial, and whether the node agrees."""
    reference = offline_verdicts(trial, model)
    offline_alarm = reference[-1].alarm_time if reference else None
    offline_class = next((v.failure_class for v in reversed(reference) if v.alarm), "")
    if rec.alarm_signal == MISMATCH:
        # raised by a classifier verdict, at the tick after it arrived over DDS: the
        # offline verifier (no beliefs) must only not have alarmed before it
        same = offline_alarm is None or (
            rec.alarm_time is not None and offline_alarm >= rec.alarm_time
        )
    else:
        same = offline_alarm == rec.alarm_time and offline_class == rec.final_class
    return {
        "offline_alarm_time": offline_alarm,
        "offline_final_class": offline_class,
        "matches_offline": same and len(reference) == rec.verdicts,
    }


def verifier_scores(
    records: Sequence[VerdictRecord],
    trials: Sequence[Trial],
    model: VerifierModel,
    offline: bool = True,
    gate_s: float = GATE_S,
) -> dict[str, Any]:
    """Per run (alarm, class, delay vs onset, offline alarm) and the protocol's summary."""
    runs: list[RunResult] = []
    per_run: list[dict[str, Any]] = []
    for rec, trial in zip(records, trials, strict=True):
        label = label_of(trial)
        onset, source = _true_onset(trial, label, model)
        run = _run_result(rec, trial, label, onset, source)
        runs.append(run)
        alarm = rec.alarm_time
        row: dict[str, Any] = {
            "trial": trial.name,
            "outcome": label.outcome,
            "failure_class": label.failure_class,
            "onset": onset,
            "onset_source": source,
            "alarm_time": alarm,
            "alarm_health": rec.alarm_health,
            "final_class": rec.final_class,
            "detection_delay_s": (
                alarm - onset if alarm is not None and onset is not None else None
            ),
            "result": _outcome(run, gate_s),
            "health_seen": rec.health_seen,
            "verdicts": rec.verdicts,
            "alarm_signal": rec.alarm_signal,
        }
        if offline:
            row.update(_offline_match(rec, trial, model))
        per_run.append(row)
    summary = metrics(runs, gate_s)
    summary.pop("class_accuracy_after_alarm_s", None)  # not observed through the nodes
    summary.pop("class_accuracy_given_onset", None)
    return {"summary": summary, "gate_s": gate_s, "runs": per_run}


def _seconds(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}s"


def verifier_summary(scores: dict[str, Any]) -> str:
    """Human-readable report of the verifier part of a replay-eval result."""
    lines = []
    for r in scores["runs"]:
        truth = r["failure_class"] or r["outcome"]
        lines.append(
            f"{r['trial']}: truth {truth} (onset {_seconds(r['onset'])}, {r['onset_source'] or '-'})"
            f"  alarm {_seconds(r['alarm_time'])} {r['alarm_health'] or ''} -> class "
            f"{r['final_class'] or '-'}, delay {_seconds(r['detection_delay_s'])}: {r['result']}"
            + (
                f"  (offline alarm {_seconds(r['offline_alarm_time'])})"
                if "offline_alarm_time" in r
                else ""
            )
        )
    s = scores["summary"]
    lines.append(
        f"verifier: detection_accuracy {s['detection_accuracy']}, recall {s['recall']}, "
        f"precision {s['precision']}, false_alarms_per_nominal_run {s['false_alarms_per_nominal_run']}, "
        f"detection_delay_s p50 {s['detection_delay_s']['p50']}, class_accuracy {s['class_accuracy']} "
        f"(gate {scores['gate_s']} s)"
    )
    return "\n".join(lines)

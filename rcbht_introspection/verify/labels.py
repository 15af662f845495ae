"""What happened in a trial, for training and scoring the verifier: outcome, failure class, onset
time and the deviation of the part, from the trial's own metadata or a hand-written labels file.

A labels file is CSV with a header row; one row per trial, empty cells for unknown values:

    trial,outcome,failure_class,onset_s,dev_x_mm,dev_y_mm,dev_yaw_deg,session
    run-07,failure,jammed,12.4,,,,day2
    run-08,success,,,,,,day2

`outcome` is success or failure; `onset_s` is the stream time (s from the trial's first sample)
of the first moment the trial's contacts differ from the nominal task's. `session` (optional
column) names the recording session: the detector's thresholds are calibrated on folds that
hold out whole sessions.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.trial import Trial

COLUMNS = ("trial", "outcome", "failure_class", "onset_s", "dev_x_mm", "dev_y_mm", "dev_yaw_deg")
SESSION = "session"
"""The optional last column: the recording session."""
DIRECTION_AXES = ("x", "y", "r")
"""Deviation axes of the characterisation: x and y offsets and yaw (r)."""
DIRECTIONS = ("-", "0", "+")
SUCCESS = "success"
FAILURE = "failure"


@dataclass(frozen=True)
class TrialLabel:
    """The truth of one trial; deviation in m, m, rad (None: no deviation label)."""

    trial: str
    outcome: str
    failure_class: str = ""
    onset: float | None = None
    deviation: tuple[float, float, float] | None = None
    line: int | None = None
    """The row of the labels file it was read from (None: the trial's own metadata)."""
    session: str = ""
    """The recording session ('' unknown)."""

    @property
    def failed(self) -> bool:
        return self.outcome == FAILURE

    def directions(self) -> dict[str, str] | None:
        """Sign of the deviation per axis (x, y, r): '-', '0' or '+'; None without deviation."""
        if self.deviation is None:
            return None
        return {a: _sign(v) for a, v in zip(DIRECTION_AXES, self.deviation, strict=True)}


def _sign(value: float) -> str:
    return "+" if value > 1e-9 else "-" if value < -1e-9 else "0"


def label_of(trial: Trial) -> TrialLabel:
    """The label a trial carries: its metadata["failure"] record (simulator, bags), else its
    outcome (a failure type without onset or deviation)."""
    record = trial.metadata.get("failure")
    session = str(trial.metadata.get("session") or "")
    if isinstance(record, Mapping):
        dev = record.get("deviation")
        deviation = None
        if isinstance(dev, Mapping):
            deviation = (
                float(dev.get("x", 0.0)),
                float(dev.get("y", 0.0)),
                float(dev.get("yaw", 0.0)),
            )
        onset = record.get("onset")
        return TrialLabel(
            trial=trial.name,
            outcome=FAILURE,
            failure_class=str(record.get("class") or trial.outcome),
            onset=None if onset is None else float(onset) - float(trial.time[0]),
            deviation=deviation,
            session=session,
        )
    if trial.outcome == SUCCESS:
        return TrialLabel(trial=trial.name, outcome=SUCCESS, session=session)
    return TrialLabel(
        trial=trial.name, outcome=FAILURE, failure_class=trial.outcome, session=session
    )


def _number(text: str, scale: float, path: Path, line: int, field: str) -> float | None:
    text = text.strip()
    if not text:
        return None
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"expected a number, got {text!r}", path, line=line, field=field) from None
    if not math.isfinite(value):
        raise InputError(f"expected a finite number, got {text!r}", path, line=line, field=field)
    return value * scale


def read_labels(path: Path | str) -> dict[str, TrialLabel]:
    """The labels file at `path`, by trial name; a bad row is a one-line error (file, line, field)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")  # a spreadsheet's byte-order mark is fine
    except OSError as exc:
        raise InputError(f"cannot read labels: {exc.strerror}", path) from None
    except UnicodeDecodeError:
        raise InputError("not UTF-8 text", path) from None
    try:
        return _parse(path, list(csv.reader(text.splitlines())))
    except csv.Error as exc:
        raise InputError(f"not CSV: {exc}", path) from None


def _parse(path: Path, table: list[list[str]]) -> dict[str, TrialLabel]:
    rows = iter(table)
    header = next(rows, None)
    names = tuple(h.strip() for h in header) if header is not None else ()
    if names not in (COLUMNS, (*COLUMNS, SESSION)):
        raise InputError(
            f"header must be {','.join(COLUMNS)}[,{SESSION}]", path, line=1, field="header"
        )
    width = len(names)
    labels: dict[str, TrialLabel] = {}
    for line, row in enumerate(rows, start=2):
        if not row or not "".join(row).strip():
            continue
        if len(row) != width:
            raise InputError(f"expected {width} cells, got {len(row)}", path, line=line)
        trial = row[0].strip()
        if not trial:
            raise InputError("empty trial name", path, line=line, field="trial")
        if trial in labels:
            raise InputError(f"trial {trial!r} labelled twice", path, line=line, field="trial")
        labels[trial] = _parse_row(path, line, row, width)
    return labels


def _parse_row(path: Path, line: int, row: list[str], width: int) -> TrialLabel:
    """One labels row (of `width` cells, a new trial name) as a TrialLabel; InputError names
    the bad cell."""
    trial, outcome, cls = (c.strip() for c in row[:3])
    if outcome not in (SUCCESS, FAILURE):
        raise InputError(
            f"expected success or failure, got {outcome!r}", path, line=line, field="outcome"
        )
    if outcome == SUCCESS and cls:
        raise InputError("a success has no failure class", path, line=line, field="failure_class")
    onset = _number(row[3], 1.0, path, line, "onset_s")
    if onset is not None and onset < 0:
        raise InputError(f"must be >= 0, got {onset}", path, line=line, field="onset_s")
    if onset is not None and outcome == SUCCESS:
        raise InputError("a success has no onset", path, line=line, field="onset_s")
    dev = [
        _number(row[4], 1e-3, path, line, "dev_x_mm"),
        _number(row[5], 1e-3, path, line, "dev_y_mm"),
        _number(row[6], math.pi / 180.0, path, line, "dev_yaw_deg"),
    ]
    deviation = None
    if any(v is not None for v in dev):
        deviation = (dev[0] or 0.0, dev[1] or 0.0, dev[2] or 0.0)
    return TrialLabel(
        trial=trial,
        outcome=outcome,
        failure_class=cls or (FAILURE if outcome == FAILURE else ""),
        onset=onset,
        deviation=deviation,
        line=line,
        session=row[7].strip() if width > len(COLUMNS) else "",
    )


def check_labels_cover(
    path: Path, labels: Mapping[str, TrialLabel], trials: Sequence[Trial], strict: bool = False
) -> list[str]:
    """The labels rows that name no given trial (one labels file may serve a training and a
    test set), in file order; with `strict` the first is a one-line error (a typo would
    otherwise make the failure it labels a success silently). An onset after its trial's end is
    an error either way."""
    by_name = {t.name: t for t in trials}  # (a name in two sets: the bound of either)
    not_given: list[str] = []
    for name, label in labels.items():
        trial = by_name.get(name)
        if trial is None:
            if strict:
                raise InputError(
                    f"trial {name!r} is not among the given trials",
                    path,
                    line=label.line,
                    field="trial",
                )
            not_given.append(name)
            continue
        end = float(trial.time[-1] - trial.time[0])
        if label.onset is not None and label.onset > end:
            raise InputError(
                f"onset {label.onset} s is after the trial's end ({end:.3f} s)",
                path,
                line=label.line,
                field="onset_s",
            )
    return not_given

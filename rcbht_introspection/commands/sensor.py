"""What the batch commands share about their input: the `--repeated-stamps` and `--strict`
options, the warnings about a trial's wrench (io/sensor_checks) and the summary of the state times
dropped from the trials (io/hiro), printed on stderr."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, cast

if TYPE_CHECKING:
    from rcbht_introspection.io.sensor_checks import RepeatedPolicy

REPEATED_CHOICES = ("error", "reject", "spread")
"""error (a repeated time stamp is an input error), or the policies of io/sensor_checks."""


def add_repeated_stamps(parser: argparse.ArgumentParser) -> None:
    """Add `--repeated-stamps` (how a time stamp equal to the previous one is read)."""
    parser.add_argument(
        "--repeated-stamps",
        choices=REPEATED_CHOICES,
        default="error",
        help="a sample stamped like the previous one: error, reject (drop it) or spread (evenly "
        "up to the next stamp); a re-sent sample (same values too) is dropped (docs/sensor-intake.md)",
    )


def repeated_policy(args: argparse.Namespace) -> RepeatedPolicy | None:
    """The policy for io/sensor_checks (None: an error)."""
    value: str = args.repeated_stamps
    return None if value == "error" else cast("RepeatedPolicy", value)


def warn(command: str, trial: str, findings: Iterable[str]) -> None:
    """One stderr line per finding: `rcbht <command>: warning: <trial>: <finding>`."""
    for line in findings:
        print(f"rcbht {command}: warning: {trial}: {line}", file=sys.stderr)


def add_strict(parser: argparse.ArgumentParser, what: str = "") -> None:
    """Add `--strict`: bad input that is otherwise dropped and counted is an error."""
    parser.add_argument(
        "--strict",
        action="store_true",
        help="stop at bad input instead of dropping and counting it: a state time after the "
        f"trial's last sample or out of order{what} (docs/your-robot.md)",
    )


def report_dropped(command: str, counts: Mapping[str, int]) -> dict[str, object]:
    """The state times dropped per trial as a JSON record ({"total", "per_trial"}), with one
    summary line on stderr when any was dropped."""
    from rcbht_introspection.io.hiro import dropped_per_trial

    record = dropped_per_trial(counts)
    per_trial = cast("dict[str, int]", record["per_trial"])
    if per_trial:
        names = list(per_trial)
        shown = ", ".join(names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")
        print(
            f"rcbht {command}: dropped {record['total']} state times after the trial's last "
            f"sample or out of order, in {len(names)} of {len(counts)} trials ({shown}); "
            "--strict makes them errors",
            file=sys.stderr,
        )
    return record

"""What the batch commands share about a trial's sensor data: the `--repeated-stamps` option and
the warnings about a trial's wrench (io/sensor_checks), printed on stderr."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable
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

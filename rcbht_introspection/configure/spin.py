"""The nodes' `spin` parameter values (no import beyond typing: the CLI's help reads them)."""

from __future__ import annotations

from typing import Literal

Spin = Literal["events", "executor"]
"""Which rclpy executor spins a node process: the EventsExecutor or the SingleThreadedExecutor."""
DEFAULT_SPIN: Spin = "events"
SPIN_HELP = (
    "events (rclpy.experimental.EventsExecutor; executor where rclpy has none) or executor "
    "(rclpy's SingleThreadedExecutor); read at start-up"
)

"""The nodes' `spin` parameter values (no import beyond typing: the CLI's help reads them)."""

from __future__ import annotations

from typing import Literal

Spin = Literal["events", "executor", "draining"]
"""How a node is spun: rclpy's EventsExecutor, its SingleThreadedExecutor, or nodes/draining.py."""
DEFAULT_SPIN: Spin = "events"
SPIN_HELP = (
    "events (rclpy.experimental.EventsExecutor; executor where rclpy has none), executor "
    "(rclpy's SingleThreadedExecutor) or draining (bursts taken through rclpy's private "
    "wait-set API, wrench decoded from CDR; executor where that API is absent); read at start-up"
)

"""The nodes' `spin` parameter values (no import beyond typing: the CLI's help reads them)."""

from __future__ import annotations

from typing import Literal

Spin = Literal["executor", "draining"]
"""How a node takes its high-rate inputs: rclpy's executor, or nodes/draining.py's bursts."""
SPIN_HELP = (
    "executor (rclpy's executor and message objects) or draining (bursts taken through rclpy's "
    "private wait-set API, wrench decoded from CDR; executor where that API is absent)"
)

"""The one polling loop of the package: wait for a condition, with a timeout and a stop request.

Nodes (bag playback), the replay harness, the benchmarks and the tests all wait for DDS
discovery, node start-up or arrivals this way; no ROS here, so every layer may use it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Protocol


class StopRequest(Protocol):
    """Anything with a `requested` flag (lifetime.py's StopSignal)."""

    @property
    def requested(self) -> bool: ...


def wait_until(
    condition: Callable[[], object],
    timeout: float = 20.0,
    *,
    poll: float = 0.02,
    stop: StopRequest | None = None,
) -> bool:
    """Poll `condition` every `poll` s: True once it holds, False after `timeout` s or a stop.

    `condition` may raise to end the wait early (a dead child process, say); the error passes.
    """
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline or (stop is not None and stop.requested):
            return False
        time.sleep(poll)
    return True

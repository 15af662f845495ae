"""RosSession: an rclpy context and node spun in a background thread, for the CLI's ROS tools."""

from __future__ import annotations

import sys
import threading
import time
from typing import Any

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import try_shutdown

from rcbht_introspection.nodes.common import serve_ready

SETTLE_CALLBACKS = 10_000
"""Most delivered callbacks `RosSession.settle` runs per round."""


class RosSession:
    """An rclpy context + node spun by a background SingleThreadedExecutor (for CLI tools).

    rclpy installs no signal handler; the caller decides what SIGINT does (a StopSignal, or
    Python's KeyboardInterrupt). `close` stops the spin thread before anything is destroyed.
    """

    def __init__(self, name: str, domain_id: int | None = None) -> None:
        self.context = Context()
        kwargs: dict[str, Any] = {"context": self.context}
        if domain_id is not None:
            kwargs["domain_id"] = domain_id
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO, **kwargs)
        self.node = Node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        # a bounded wait, so the thread sees the stop request without the context going away
        reported = False
        while not self._stop.is_set() and self.context.ok():
            try:
                self.executor.spin_once(timeout_sec=0.05)
            except Exception as exc:
                if not reported:  # said once, on one line; the session keeps serving
                    print(f"error in a callback: {type(exc).__name__}: {exc}", file=sys.stderr)
                    reported = True

    def settle(self, timeout: float = 2.0) -> None:
        """Stop the spin thread, then run every callback whose message was already delivered."""
        self._stop.set()
        self._thread.join()
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                if not serve_ready(self.executor, SETTLE_CALLBACKS):
                    return
            except Exception as exc:
                print(f"error in a callback: {type(exc).__name__}: {exc}", file=sys.stderr)

    def close(self) -> None:
        """Stop the spin thread, then destroy the node and shut the context down, in that order."""
        self._stop.set()
        self._thread.join()
        self.executor.shutdown(timeout_sec=0)
        self.node.destroy_node()  # type: ignore[no-untyped-call]
        try_shutdown(context=self.context)

    def __enter__(self) -> RosSession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

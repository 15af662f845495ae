"""How a process of ours ends: SIGINT/SIGTERM only ask it to stop; it stops where it checks.

No rclpy here (imported before anything heavy), so a signal during start-up is caught as well:
Python's default SIGINT handler would raise KeyboardInterrupt inside whatever import or rclpy
call runs, and rclpy's own handler shuts the context down under a running node (publishers
then fail). With a StopSignal the process finishes its step, logs its last line and shuts down
in order; a watchdog ends a stop that hangs, with the stack of every thread in the log.
"""

from __future__ import annotations

import faulthandler
import os
import signal
import sys
import threading

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_EXITING = threading.Event()
WATCHDOG_S = 10.0
"""A process that has not exited this long after the stop request dumps its stacks and exits 3."""


class StopSignal:
    """SIGINT / SIGTERM set `requested`; the owner checks it (and may wait on it) and stops."""

    def __init__(self, watchdog_s: float = WATCHDOG_S) -> None:
        self.event = threading.Event()
        self.signum: int | None = None
        self.watchdog_s = watchdog_s

    @classmethod
    def install(cls, watchdog_s: float = WATCHDOG_S) -> StopSignal:
        """Replace the SIGINT and SIGTERM handlers of this process (main thread only)."""
        stop = cls(watchdog_s)
        for signum in STOP_SIGNALS:
            signal.signal(signum, stop._handle)
        faulthandler.enable()  # a crash in native code leaves the Python stack in the log
        return stop

    @property
    def requested(self) -> bool:
        return self.event.is_set()

    def request(self) -> None:
        """Ask for a stop as a signal would (tests, or a node that decides to end)."""
        if not self.event.is_set():
            self.event.set()
            if self.watchdog_s > 0:
                threading.Thread(target=self._watchdog, name="stop-watchdog", daemon=True).start()

    def wait(self, timeout: float | None = None) -> bool:
        """Block until a stop is requested or `timeout` passed; True if requested."""
        return self.event.wait(timeout)

    @staticmethod
    def exiting() -> None:
        """The process is done with its own shutdown (the watchdog stands down)."""
        _EXITING.set()

    def _handle(self, signum: int, frame: object) -> None:
        self.signum = self.signum or signum
        self.request()

    def _watchdog(self) -> None:
        # still running this long after the request: whatever holds it up is a bug to see
        if not _EXITING.wait(self.watchdog_s):
            print(
                f"stop did not complete within {self.watchdog_s:.0f} s; stacks follow",
                file=sys.stderr,
                flush=True,
            )
            faulthandler.dump_traceback(all_threads=True)
            os._exit(3)

"""How a process of ours ends: SIGINT/SIGTERM only ask it to stop; it stops where it checks.

No rclpy here (imported before anything heavy), so a signal during start-up is caught as well:
Python's default SIGINT handler would raise KeyboardInterrupt inside whatever import or rclpy
call runs, and rclpy's own handler shuts the context down under a running node (publishers
then fail). With a StopSignal the process finishes its step, logs its last line and shuts down
in order; a watchdog ends a stop that hangs, with the stack of every thread in the log. It is
faulthandler's, a thread of C that needs no GIL: a hang inside a library's native shutdown (a
DDS participant's destructor holding the GIL) is dumped and ended as well.
The handler only sets a flag and the interpreter's wake-up byte lands in a pipe: it takes no
lock, so it cannot deadlock whatever the main thread was doing when the signal came.
A node process installs it with `until_up=True`: a stop during start-up (imports, configure,
model loading: seconds on a loaded machine) ends the process at once with exit 0, since nothing
needs an orderly shutdown before the node is up; `up()` switches to the flag.
"""

from __future__ import annotations

import contextlib
import faulthandler
import gc
import os
import select
import signal
import sys
import threading
import time

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
WATCHDOG_S = 10.0
"""A process that has not exited this long after the stop request dumps its stacks and exits 1."""


class StopSignal:
    """SIGINT / SIGTERM set `requested`; the owner checks it (or waits on it) and stops."""

    def __init__(self, watchdog_s: float = WATCHDOG_S, until_up: bool = False) -> None:
        self.watchdog_s = watchdog_s
        self._exit_now = until_up
        """A stop ends the process at once (start-up): until `up()`."""
        self.signum: int | None = None
        self._requested = False
        self._watched = False
        """Installed: a stop request arms the watchdog."""
        self._read, self._write = os.pipe()
        for fd in (self._read, self._write):
            os.set_blocking(fd, False)

    @classmethod
    def install(cls, watchdog_s: float = WATCHDOG_S, until_up: bool = False) -> StopSignal:
        """Replace the SIGINT and SIGTERM handlers of this process (main thread only);
        `until_up`: a stop before `up()` exits at once (exit 0)."""
        stop = cls(watchdog_s, until_up)
        signal.set_wakeup_fd(stop._write, warn_on_full_buffer=False)
        for signum in STOP_SIGNALS:
            signal.signal(signum, stop._handle)
        faulthandler.enable()  # a crash in native code leaves the Python stack in the log
        stop._watched = True
        return stop

    def up(self) -> None:
        """Start-up is over: from now on a stop only sets the flag (orderly shutdown)."""
        self._exit_now = False

    @property
    def requested(self) -> bool:
        return self._requested

    def is_set(self) -> bool:
        """Same as `requested` (lets a StopSignal stand where a threading.Event is checked)."""
        return self._requested

    def request(self) -> None:
        """Ask for a stop as a signal would (tests, or a node that decides to end)."""
        self._arm()
        self._requested = True
        with contextlib.suppress(BlockingIOError):
            os.write(self._write, b"\0")

    def wait(self, timeout: float | None = None) -> bool:
        """Block until a stop is requested or `timeout` passed; True if requested."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while not self._requested:
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                break
            # a signal writes its wake-up byte to the pipe: select returns at once
            select.select([self._read], [], [], left)
            with contextlib.suppress(BlockingIOError):
                os.read(self._read, 512)
        return self._requested

    def exiting(self) -> None:
        """The process is done with its own shutdown; further SIGINT/SIGTERM are ignored (Python
        restores the default action of a signal it handled while the interpreter finalizes, so a
        second Ctrl-C would end the process with -2). The watchdog stays armed: the interpreter's
        finalization (thread joins, native destructors) can hang too."""
        if threading.current_thread() is threading.main_thread():
            for signum in STOP_SIGNALS:
                signal.signal(signum, signal.SIG_IGN)

    def _handle(self, signum: int, frame: object) -> None:
        if self._exit_now:  # start-up: nothing to shut down in order yet
            with contextlib.suppress(Exception):  # a write the signal interrupted may refuse
                sys.stdout.flush()
                sys.stderr.flush()
            os._exit(0)
        if self.signum is None:
            self.signum = signum
        self._arm()
        self._requested = True
        # our own wake-up byte too, in case a library replaced the interpreter's wake-up fd
        with contextlib.suppress(OSError):
            os.write(self._write, b"\0")

    def _arm(self) -> None:
        """At the first stop request: dump every thread's stack and exit 1 if the process still
        runs `watchdog_s` later (faulthandler's timer thread runs without the GIL)."""
        if self._watched and not self._requested and self.watchdog_s > 0:
            faulthandler.dump_traceback_later(self.watchdog_s, exit=True)


def keep_out_of_collector() -> None:
    """Collect, then freeze what the process holds now: it lives on, and the cyclic collector's
    full passes over it would stall a 1 kHz callback or player for tens of milliseconds."""
    gc.collect()
    gc.freeze()

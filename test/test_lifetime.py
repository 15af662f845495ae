"""StopSignal (nodes/lifetime.py) in a real process: what SIGINT/SIGTERM do before and after up()."""

from __future__ import annotations

import signal
import subprocess
import sys

import pytest

BUSY_START_UP = """
import sys, time
from rcbht_introspection.nodes.lifetime import StopSignal
stop = StopSignal.install(until_up=True)
if {up}:
    stop.up()
print("ready", flush=True)
t = time.monotonic()
while not stop.requested and time.monotonic() - t < 60:
    sum(range(10_000))  # an import or a model load: Python code that never checks the flag
print("stopped in order" if stop.requested else "never stopped", flush=True)
stop.exiting()
"""


def _run(up: bool, signum: int) -> tuple[int, str]:
    proc = subprocess.Popen(
        [sys.executable, "-c", BUSY_START_UP.format(up=up)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "ready"
    proc.send_signal(signum)
    out, _ = proc.communicate(timeout=30)
    return proc.returncode, out


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_stop_during_start_up_ends_the_process_at_once(signum: int) -> None:
    code, out = _run(up=False, signum=signum)
    assert code == 0 and out == ""  # no traceback, and the busy start-up did not go on


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_stop_once_up_only_asks(signum: int) -> None:
    code, out = _run(up=True, signum=signum)
    assert code == 0 and out.strip() == "stopped in order"

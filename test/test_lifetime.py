"""How our processes end: StopSignal (lifetime.py) in a real process, before and after
up(); and SIGTERM of a harness that runs node processes."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import SIM_SUCCESS
from ros_support import require_ros, ros_env

from rcbht_introspection.replay.supervision import stop_process
from rcbht_introspection.waiting import wait_until

BUSY_START_UP = """
import sys, time
from rcbht_introspection.lifetime import StopSignal
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


HUNG_SHUTDOWN = """
import ctypes
from rcbht_introspection.lifetime import StopSignal
stop = StopSignal.install(watchdog_s=1.0)
stop.up()
print("ready", flush=True)
stop.wait()
stop.exiting()
ctypes.PyDLL(None).sleep(60)  # a native destructor that hangs with the GIL held
"""


def test_a_shutdown_hung_in_native_code_is_dumped_and_ended() -> None:
    """The watchdog needs no GIL and stays armed through the process's own exit."""
    proc = subprocess.Popen(
        [sys.executable, "-c", HUNG_SHUTDOWN],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
    start = time.monotonic()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 1 and time.monotonic() - start < 20
    assert "Timeout (0:00:01)!" in err and '<string>", line 9' in err, err


def _children(pid: int) -> list[int]:
    """Pids of the live processes whose parent is `pid` (from /proc)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] != "Z":
            out.append(int(stat.parent.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.ros
def test_sigterm_of_replay_eval_stops_its_node_processes(sim_data: Path, tmp_path: Path) -> None:
    """SIGTERM, as a supervisor sends it, ends `rcbht replay-eval` as Ctrl-C does: exit 0 and
    both node processes stopped, none left running without their harness."""
    require_ros()
    from rcbht_introspection.io.bags import write_trial_bag
    from rcbht_introspection.io.hiro import find_trials, read_trial
    from rcbht_introspection.learn.data import load_samples
    from rcbht_introspection.learn.model_file import save_model
    from rcbht_introspection.learn.models import train_model

    folders = find_trials([sim_data / SIM_SUCCESS])
    bag = tmp_path / "trial.mcap"
    write_trial_bag(read_trial(folders[-1]), bag)
    model = save_model(
        train_model(load_samples(folders[:-1], words="engine"), "svm", "compact"),
        tmp_path / "model.rcbht",
    )
    command = ["replay-eval", str(bag), "--model", str(model), "--rate", "1"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "rcbht_introspection.cli", *command],
        env=ros_env(tmp_path),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        assert wait_until(lambda: len(_children(proc.pid)) >= 2, timeout=120), "no node processes"
        nodes = _children(proc.pid)
        time.sleep(1.0)  # the nodes are starting or playing: either way they must be stopped
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=60)
    finally:
        stop_process(proc)
    assert proc.returncode == 0, out
    assert wait_until(lambda: not any(_alive(p) for p in nodes), timeout=20), out

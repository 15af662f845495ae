"""Node processes of a test, replay or benchmark: an isolated ROS environment, start, wait, stop.

Each run leases a ROS_DOMAIN_ID (1..101) of its own and discovers over loopback only
(ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and config/fastdds_localhost.xml), with its logs in a
ROS_LOG_DIR of its own. No rclpy here: the children run the nodes, this module only supervises.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import IO, Any

import yaml

import rcbht_introspection
from rcbht_introspection.config_files import config_path
from rcbht_introspection.configure.params import NODE_NAMES
from rcbht_introspection.errors import InputError
from rcbht_introspection.waiting import wait_until

DOMAIN_IDS = range(1, 102)
"""ROS_DOMAIN_IDs whose DDS ports stay below the Linux ephemeral range."""
_LEASES: dict[int, IO[str]] = {}


def lease_domain() -> int:
    """A ROS_DOMAIN_ID that no other process of this machine holds, held until released.

    Each id is a lock file (flock) under the temp directory; the lock goes with the process,
    so a crashed holder frees its id. Tests, replays and benchmarks that run at the same time
    therefore never share a DDS domain.
    """
    folder = Path(tempfile.gettempdir()) / "rcbht-ros-domains"
    folder.mkdir(exist_ok=True)
    ids = [i for i in DOMAIN_IDS if i not in _LEASES]
    random.SystemRandom().shuffle(ids)
    for domain_id in ids:
        handle = (folder / f"{domain_id}.lock").open("a")
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.close()
            continue
        _LEASES[domain_id] = handle
        return domain_id
    raise InputError(f"every ROS_DOMAIN_ID in {DOMAIN_IDS.start}..{DOMAIN_IDS.stop - 1} is in use")


def release_domain(domain_id: int | None = None) -> None:
    """Give back a leased domain (None: every domain this process holds)."""
    for i in list(_LEASES) if domain_id is None else [domain_id]:
        handle = _LEASES.pop(i, None)
        if handle is not None:
            handle.close()  # closing the file drops its lock


def ros_env(domain_id: int, log_dir: Path) -> dict[str, str]:
    """Environment that isolates a ROS graph on this host: private domain, loopback only."""
    return {
        "ROS_DOMAIN_ID": str(domain_id),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "ROS_LOG_DIR": str(log_dir),
        "FASTRTPS_DEFAULT_PROFILES_FILE": str(config_path("fastdds_localhost.xml")),
        "RCUTILS_COLORIZED_OUTPUT": "0",
    }


@contextlib.contextmanager
def environment(values: dict[str, str]) -> Iterator[None]:
    """Set environment variables for this process for the duration of the block."""
    old = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    os.environ.pop("ROS_LOCALHOST_ONLY", None)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def write_params(path: Path, cls: type, values: dict[str, Any]) -> Path:
    """A ROS parameter file for one node."""
    path.write_text(yaml.safe_dump({NODE_NAMES[cls]: {"ros__parameters": values}}))
    return path


def node_command(module: str, *ros_args: str) -> list[str]:
    """Command line that starts node `module` as its own process (`python -m ...nodes NODE`)."""
    return [sys.executable, "-m", "rcbht_introspection.nodes", module, "--ros-args", *ros_args]


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """While the block runs, SIGTERM (a supervisor, `kill`) raises KeyboardInterrupt as Ctrl-C
    does, so the finally blocks that stop child node processes run; the old handler comes back
    after (main thread only: elsewhere the block runs unchanged)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def stop_process(
    proc: subprocess.Popen[Any], timeout: float = 20.0, signum: int | None = signal.SIGINT
) -> int | None:
    """Send `signum` (None: it was sent already), wait `timeout` s, then SIGKILL.

    The exit code, or None when it had to be killed. Our processes stop cleanly on SIGINT.
    """
    if proc.poll() is not None:
        return proc.returncode
    if signum is not None:
        proc.send_signal(signum)
    try:
        return proc.wait(timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        with contextlib.suppress(subprocess.TimeoutExpired):  # only a process stuck in the kernel
            proc.wait(5)
        return None


class NodeProcess:
    """One node as a child process (`python -m rcbht_introspection.nodes <module>`)."""

    def __init__(self, module: str, params: Path, env: dict[str, str], log: Path) -> None:
        self.name = module
        self.log = log
        pkg_root = str(Path(rcbht_introspection.__file__).resolve().parents[1])
        full_env = {**os.environ, **env}
        full_env["PYTHONPATH"] = os.pathsep.join(
            p for p in (pkg_root, os.environ.get("PYTHONPATH", "")) if p
        )
        full_env.pop("ROS_LOCALHOST_ONLY", None)
        self.interrupted = False
        self._log_file = log.open("w")
        self.proc = subprocess.Popen(
            node_command(module, "--params-file", str(params)),
            env=full_env,
            stdout=self._log_file,
            stderr=subprocess.STDOUT,
        )

    def alive(self) -> bool:
        """The process has not exited yet."""
        return self.proc.poll() is None

    def tail(self, lines: int = 15) -> str:
        """The last `lines` of the node's log ("" if it cannot be read)."""
        try:
            return "\n".join(self.log.read_text().splitlines()[-lines:])
        except OSError:
            return ""

    def interrupt(self) -> None:
        """Send SIGINT (the node stops cleanly); `stop` waits for it."""
        if self.proc.poll() is None and not self.interrupted:
            self.proc.send_signal(signal.SIGINT)
            self.interrupted = True

    def stop(self, timeout: float = 20.0) -> int | None:
        """SIGINT, then SIGKILL after `timeout`; returns the exit code (None if it was killed)."""
        try:
            self.interrupt()  # once: a second SIGINT is not a harder stop
            return stop_process(self.proc, timeout, signum=None)
        finally:
            self._log_file.close()


def wait_for_nodes(
    condition: Callable[[], object],
    timeout: float,
    procs: Sequence[NodeProcess],
    what: str,
    progress: Callable[[], str] | None = None,
) -> float:
    """Wait for `condition` while the nodes run; the seconds it took.

    A node that exits, or `timeout`, raises InputError with the nodes' log tails (and `progress`).
    """
    t0 = time.monotonic()

    def held() -> bool:
        if condition():
            return True
        for p in procs:
            if not p.alive():
                raise InputError(f"{p.name} exited (code {p.proc.returncode}):\n{p.tail()}")
        return False

    if not wait_until(held, timeout, poll=0.05):
        logs = "\n".join(f"--- {p.name}\n{p.tail()}" for p in procs)
        got = f" ({progress()})" if progress is not None else ""
        raise InputError(f"timed out after {timeout:.0f} s waiting for {what}{got}\n{logs}")
    return time.monotonic() - t0

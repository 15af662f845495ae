"""An OnlineLearner in a process of its own, so that learning never holds the live path's GIL.

The process is a fresh interpreter (`python -m rcbht_introspection.learn.learner_process`: never
a fork of a parent that may run DDS threads, and it imports no ROS) in a session of its own, so
a terminal's Ctrl-C reaches only the parent, which ends it by closing the connection. Taught
windows go to it over a multiprocessing Connection on a socket pair (our own dataclasses between
our own processes); each taught model comes back as a safe model file (learn/model_file.py:
checksum, atomic write, no pickle) that the parent loads, so a model object never crosses the
connection. The given starting model goes the same way, as a file the parent writes.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection
from pathlib import Path

from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar.split import SubtaskSample
from rcbht_introspection.learn.model_file import load_model, save_model
from rcbht_introspection.learn.models import SubtaskModel
from rcbht_introspection.learn.online import OnlineLearner, TeachConfig

MODULE = "rcbht_introspection.learn.learner_process"
"""What the learner process runs (`python -m`)."""
START_TIMEOUT_S = 120.0
"""Longest wait for the spawned learner to import and load its starting model."""


@dataclass(frozen=True)
class _Start:
    """What the learner process needs to build its OnlineLearner."""

    config: TeachConfig
    model_path: str
    """The starting model's file, '' for a cold start."""
    random_state: int
    taxonomy_profile: str
    out_path: str
    """Where each taught model is written (the teach file, else a file in a temporary folder)."""
    fallback_path: str
    """Where it is written when out_path cannot be (in the parent's temporary folder)."""


@dataclass(frozen=True)
class TaughtFile:
    """The learner's answer to one teach: the model's file, or why there is none."""

    path: str = ""
    save_error: str = ""
    """The teach file could not be written; the model is then in `path`, a fallback file."""
    error: str = ""
    """'' on success; else 'Type: message' of what failed (nothing was changed then)."""


def _serve(conn: Connection, start: _Start) -> None:
    """The learner process: teach what arrives, answer with a TaughtFile, until the connection
    closes or the parent is gone (then nothing more is written: a restarted node may own the
    teach file by now)."""
    parent = os.getppid()
    model = load_model(start.model_path) if start.model_path else None
    learner = OnlineLearner(
        start.config, model, model.task if model else None, start.random_state,
        taxonomy_profile=start.taxonomy_profile,
    )  # fmt: skip
    conn.send(TaughtFile())
    while True:
        try:
            job = conn.recv()
        except (EOFError, OSError):
            return  # the parent closed the connection or is gone
        if job is None:
            return
        samples, live = job
        try:
            taught = learner.teach(samples, live)
        except Exception as exc:  # answered, never raised: the parent counts it
            answer = TaughtFile(error=f"{type(exc).__name__}: {exc}")
        else:
            if os.getppid() != parent:
                return
            try:
                answer = TaughtFile(str(save_model(taught, start.out_path, compress=False)))
            except OSError as exc:  # the parent still gets the model, from the fallback file
                answer = TaughtFile(
                    str(save_model(taught, start.fallback_path, compress=False)), str(exc)
                )
        try:
            conn.send(answer)
        except OSError:
            return  # the parent is gone


class ProcessLearner:
    """OnlineLearner.teach run in a process of its own; `teach` blocks its caller (the teach
    worker thread) on the connection, which holds no GIL, and loads the taught model's file."""

    def __init__(
        self,
        config: TeachConfig,
        model: SubtaskModel | None = None,
        out_path: str | Path = "",
        random_state: int = 0,
        taxonomy_profile: str = "reference",
    ) -> None:
        self._folder = tempfile.TemporaryDirectory(prefix="rcbht-teach-")
        folder = Path(self._folder.name)
        start_path = ""
        if model is not None:
            start_path = str(save_model(model, folder / "start.rcbht", compress=False))
        self.out_path = Path(out_path) if out_path else folder / "taught.rcbht"
        """Where the taught models are written: the teach file when one is given."""
        ours, theirs = socket.socketpair()
        package_root = str(Path(__file__).resolve().parents[2])  # the child imports this package
        env = {**os.environ}
        env["PYTHONPATH"] = os.pathsep.join(p for p in (package_root, env.get("PYTHONPATH")) if p)
        with theirs:
            self._process = subprocess.Popen(
                [sys.executable, "-m", MODULE, str(theirs.fileno())],
                pass_fds=(theirs.fileno(),),
                stdin=subprocess.DEVNULL,
                env=env,
                start_new_session=True,
            )
        self._conn = Connection(ours.detach())
        self._conn.send(
            _Start(
                config,
                start_path,
                random_state,
                taxonomy_profile,
                str(self.out_path),
                str(folder / "fallback.rcbht"),
            )
        )
        self._started = False

    def teach(
        self, samples: Sequence[SubtaskSample], live: Sequence[SubtaskSample] = ()
    ) -> tuple[SubtaskModel, str]:
        """The model taught `samples` (and `live`), loaded from its file, and a line saying why
        the teach file was not written ('' when it was). Raises InputError when the learner
        refused or failed (nothing changed) and RuntimeError when its process is gone."""
        self._wait_started()
        try:
            self._conn.send((list(samples), list(live)))
            answer: TaughtFile = self._conn.recv()
        except (EOFError, OSError) as exc:
            raise RuntimeError(self._gone(exc)) from exc
        if answer.error:
            raise InputError(f"the learner refused: {answer.error}")
        return load_model(answer.path), answer.save_error

    @property
    def pid(self) -> int:
        """The learner process's id."""
        return self._process.pid

    @property
    def alive(self) -> bool:
        """The learner process runs."""
        return self._process.poll() is None

    def _wait_started(self) -> None:
        if self._started:
            return
        if not self._conn.poll(START_TIMEOUT_S):
            raise RuntimeError(f"the learner process did not start within {START_TIMEOUT_S} s")
        try:
            self._conn.recv()
        except (EOFError, OSError) as exc:
            raise RuntimeError(self._gone(exc)) from exc
        self._started = True

    def _gone(self, exc: BaseException) -> str:
        with contextlib.suppress(subprocess.TimeoutExpired):
            self._process.wait(10.0)  # reaped, so the exit code is known
        return (
            f"the learner process ended (exit code {self._process.returncode}): "
            f"{type(exc).__name__}: {exc}"
        )

    def close(self, timeout: float = 10.0) -> None:
        """End the process (it finishes the teach under way first, else it is killed after
        `timeout`) and remove its files. The connection is closed only once the process is gone,
        so a teach still waiting on it ends with EOF, not on a closed handle."""
        with contextlib.suppress(OSError):  # the process is gone already
            self._conn.send(None)
        try:
            self._process.wait(timeout)
        except subprocess.TimeoutExpired:
            self._process.kill()
            self._process.wait(timeout)
        self._conn.close()
        self._folder.cleanup()


def main(argv: Sequence[str] | None = None) -> int:
    """The learner process: argv[0] is the file descriptor of its end of the connection."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent ends it (closes the connection)
    args = list(sys.argv[1:] if argv is None else argv)
    conn = Connection(int(args[0]))
    start = conn.recv()
    _serve(conn, start)
    return 0


if __name__ == "__main__":
    # run as the package's module, not as __main__: what it pickles must name the package's classes
    from rcbht_introspection.learn import learner_process

    sys.exit(learner_process.main())

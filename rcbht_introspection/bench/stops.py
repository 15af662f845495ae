"""Stop robustness: SIGINT at random moments under 1 kHz wrench traffic, real processes and DDS.

Each node (and `rcbht bag record`) is started as its own process and sent SIGINT at a random
moment, a third of them during start-up (imports, rclpy.init, configure, waiting for topics),
counted from the moment the process's stop handler is installed. A stop is clean when the process exits 0 within STOP_LIMIT_S, its
output holds no traceback and no error line, a node that got to active logged its statistics
line, and a recorded bag reads back. `python -m rcbht_introspection.bench --only stops` runs
RCBHT_STOPS_NODE (default 100) stops per node and RCBHT_STOPS_RECORD (default 50) recordings;
test/test_stops.py runs a few of each.
"""

from __future__ import annotations

import math
import os
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import rclpy
from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from rclpy.utilities import try_shutdown
from std_msgs.msg import String

from rcbht_introspection.grammar.split import SubtaskSample
from rcbht_introspection.io.bags import bag_messages
from rcbht_introspection.learn.model_file import save_model
from rcbht_introspection.learn.models import train_model
from rcbht_introspection.messages import to_time
from rcbht_introspection.nodes.common import qos_profile
from rcbht_introspection.replay.supervision import (
    environment,
    lease_domain,
    node_command,
    ros_env,
    stop_process,
)
from rcbht_introspection.rostools.session import RosSession
from rcbht_introspection.taxonomy.words import Level, TrialWords, Word
from rcbht_introspection.waiting import wait_until

STOP_LIMIT_S = 5.0
RATE_HZ = 1000.0
PHASES = ("approach", "rotation", "insertion", "mating", "done")
STATS_LINE = {
    "segmenter_node": "samples (accepted, rejected)",
    "classifier_node": "beliefs published",
}
UP_LINE = {"segmenter_node": "arms [", "classifier_node": "mode boundary"}
BAD_MARKERS = ("Traceback", "[ERROR]", "error:", "Failed to publish", "Segmentation fault")


@dataclass(frozen=True)
class Stop:
    """One SIGINT stop and how it went."""

    kind: str
    delay_s: float
    up: bool
    """The process had logged that it was up (active / recording) before the signal."""
    code: int | None
    seconds: float
    bad_lines: tuple[str, ...]
    stats_logged: bool
    bag_ok: bool | None = None

    @property
    def clean(self) -> bool:
        return (
            self.code == 0
            and self.seconds <= STOP_LIMIT_S
            and not self.bad_lines
            and (self.stats_logged or not self.up or self.kind == "bag_record")
            and self.bag_ok is not False
        )


class WrenchTraffic:
    """1 kHz WrenchStamped on /wrench and a sub-task event every 2 s, from a background thread."""

    def __init__(self, ros: Any) -> None:

        qos = qos_profile(1000, "reliable")
        self.wrench = ros.node.create_publisher(WrenchStamped, "/wrench", qos)
        self.phase = ros.node.create_publisher(String, "/task_phase", qos)
        self.msg_type, self.event_type = WrenchStamped, String
        self.sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:

        t0 = time.perf_counter()
        n = 0
        while not self._stop.is_set():
            due = int((time.perf_counter() - t0) * RATE_HZ)
            while n < due:
                if n % 2000 == 0:
                    self.phase.publish(self.event_type(data=PHASES[(n // 2000) % len(PHASES)]))
                msg = self.msg_type()
                msg.header.stamp = to_time(time.time_ns())
                msg.wrench.force.z = 10 * math.sin(n / 150) + (n // 700 % 3) * 4
                msg.wrench.torque.x = math.cos(n / 230)
                self.wrench.publish(msg)
                n += 1
            self.sent = n
            time.sleep(0.002)

    def close(self) -> None:
        self._stop.set()
        self._thread.join()


TOY_LABELS = ("bpos", "cons", "bneg", "pimp")


def toy_model(
    path: Path, classes: tuple[str, ...] = ("approach", "rotation", "insertion", "mating")
) -> Path:
    """A small sub-task model (one hand-made Fz word per sample) for a node under test."""

    samples = []
    for i in range(2 * len(classes)):
        subtask, label = classes[i % len(classes)], TOY_LABELS[i % len(classes)]
        tw = TrialWords(name=f"t{i}")
        tw.add(Word("Fz", Level.PRIMITIVE, label, 0.0, 1.0 + i, arm="R"))
        samples.append(SubtaskSample(f"t{i}", subtask, 0.0, 1.0 + i, tw))
    save_model(train_model(samples), path)
    return path


def _node_command(kind: str, work: Path) -> list[str]:
    if kind == "classifier_node":
        return node_command(kind, "-p", f"model_file:={work / 'model.rcbht'}")
    return node_command(kind, "-p", "stream_profile:=causal")


def handles_sigterm(pid: int) -> bool:
    """The process has installed a SIGTERM handler (its StopSignal): /proc/PID/status SigCgt.

    Python catches SIGINT from its own start, but only our StopSignal catches SIGTERM; the
    first ~0.1-0.3 s of a process (interpreter start, the ROS wheels' re-exec, the first
    imports) come before it.
    """
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("SigCgt:"):
                return bool(int(line.split()[1], 16) & (1 << (signal.SIGTERM - 1)))
    except OSError:
        pass
    return False


def stop_once(kind: str, work: Path, env: dict[str, str], rng: random.Random, i: int) -> Stop:
    """Start one process of `kind`, SIGINT it at a random moment, judge the stop."""
    log = work / f"{kind}-{i}.log"
    bag = work / f"rec-{i}.mcap"
    if kind == "bag_record":
        cmd = [sys.executable, "-m", "rcbht_introspection.cli", "bag", "record", "/wrench"]
        cmd += ["--out", str(bag), "--wait", "20"]
        up_line = "recording"
    else:
        cmd = _node_command(kind, work)
        up_line = UP_LINE[kind]
    # a third of the stops come during start-up (imports, rclpy.init, configure)
    during_startup = rng.random() < 1 / 3
    with log.open("w") as out:
        proc = subprocess.Popen(cmd, env=env, stdout=out, stderr=subprocess.STDOUT)
    started = time.monotonic()
    if during_startup:
        # from the moment the process's own stop handler is in (before it, the interpreter
        # and its start-up are not ours to stop cleanly; see handles_sigterm)
        wait_until(lambda: handles_sigterm(proc.pid) or proc.poll() is not None, 60, poll=0.005)
        time.sleep(rng.uniform(0.0, 1.0))
        delay = time.monotonic() - started
    else:
        wait_until(lambda: up_line in log.read_text() or proc.poll() is not None, 60)
        time.sleep(rng.uniform(0.2, 2.5))
        delay = time.monotonic() - started
    up = up_line in log.read_text()
    t0 = time.monotonic()
    code = stop_process(proc, STOP_LIMIT_S * 3)
    seconds = time.monotonic() - t0
    text = log.read_text()
    bad = tuple(line for line in text.splitlines() if any(m in line for m in BAD_MARKERS))
    bag_ok = None
    if kind == "bag_record" and up:
        try:
            sum(1 for _ in bag_messages(bag))
            bag_ok = True
        except Exception:
            bag_ok = False
        bag.unlink(missing_ok=True)
    stats = kind in STATS_LINE and STATS_LINE[kind] in text
    return Stop(kind, round(delay, 3), up, code, round(seconds, 3), bad, stats, bag_ok)


def stop_loop(
    n_node: int, n_record: int, work: Path, seed: int = 0
) -> tuple[list[Stop], dict[str, int]]:
    """Stops of segmenter_node, classifier_node (fed by a running segmenter) and bag record."""

    rng = random.Random(seed)
    values = ros_env(lease_domain(), work / "ros_log")
    env = {**os.environ, **values}
    env.pop("ROS_LOCALHOST_ONLY", None)
    toy_model(work / "model.rcbht")
    stops: list[Stop] = []
    sent = {}
    with environment(values), RosSession("stop_loop", domain_id=int(env["ROS_DOMAIN_ID"])) as ros:
        traffic = WrenchTraffic(ros)
        try:
            for i in range(n_node):
                stops.append(stop_once("segmenter_node", work, env, rng, i))
            feeder = subprocess.Popen(
                _node_command("segmenter_node", work),
                env=env,
                stdout=(work / "feeder.log").open("w"),
                stderr=subprocess.STDOUT,
            )
            try:
                for i in range(n_node):
                    stops.append(stop_once("classifier_node", work, env, rng, i))
            finally:
                stop_process(feeder, 30)
            for i in range(n_record):
                stops.append(stop_once("bag_record", work, env, rng, i))
        finally:
            traffic.close()
        sent["wrench_published"] = traffic.sent
    return stops, sent


def _first_message() -> None:
    """Child of `match_gaps`: subscribe to /match_probe, print (subscribed ns, first stamp ns)."""

    rclpy.init()
    node = Node("match_probe_reader")
    first: list[int] = []

    def on_probe(msg: String) -> None:
        first.append(int(msg.data))

    node.create_subscription(String, "/match_probe", on_probe, 1000)
    subscribed = time.time_ns()
    while not first:
        rclpy.spin_once(node, timeout_sec=0.1)
    print(subscribed, first[0], flush=True)
    node.destroy_node()  # type: ignore[no-untyped-call]
    try_shutdown()


def match_gaps(n: int, work: Path, seed: int = 0) -> list[float]:
    """Seconds between a new subscriber's creation and the first message it gets (1 kHz topic).

    With volatile durability, what the publisher sends in this gap never reaches the new
    subscriber: the window in which a (re)started classifier misses words.
    """

    env = {**os.environ, **ros_env(lease_domain(), work / "ros_log")}
    env.pop("ROS_LOCALHOST_ONLY", None)
    gaps = []
    with RosSession("match_probe_writer", domain_id=int(env["ROS_DOMAIN_ID"])) as ros:
        pub = ros.node.create_publisher(String, "/match_probe", 1000)
        done = threading.Event()

        def publish() -> None:
            while not done.wait(0.001):
                pub.publish(String(data=str(time.time_ns())))

        thread = threading.Thread(target=publish, daemon=True)
        thread.start()
        code = "from rcbht_introspection.bench.stops import _first_message; _first_message()"
        try:
            for _ in range(n):
                out = subprocess.run(
                    [sys.executable, "-c", code], env=env, capture_output=True, text=True,
                    timeout=60, check=True,
                )  # fmt: skip
                subscribed, first = (int(v) for v in out.stdout.split())
                gaps.append((first - subscribed) / 1e9)
        finally:
            done.set()
            thread.join()
    return gaps


def summarise(stops: list[Stop]) -> dict[str, Any]:
    """Per kind: stops, clean stops, during start-up, slowest stop, the unclean ones."""
    out: dict[str, Any] = {}
    for kind in ("segmenter_node", "classifier_node", "bag_record"):
        mine = [s for s in stops if s.kind == kind]
        if not mine:
            continue
        secs = sorted(s.seconds for s in mine)
        out[kind] = {
            "stops": len(mine),
            "clean": sum(s.clean for s in mine),
            "during_startup": sum(not s.up for s in mine),
            "exit_seconds_p50": secs[len(secs) // 2],
            "exit_seconds_max": secs[-1],
            "unclean": [asdict(s) for s in mine if not s.clean],
        }
    return out


def run(out_dir: Path) -> dict[str, Any]:
    """`make bench`-style entry (optional module): the full loop, summarised."""
    n_node = int(os.environ.get("RCBHT_STOPS_NODE", "100"))
    n_record = int(os.environ.get("RCBHT_STOPS_RECORD", "50"))
    with tempfile.TemporaryDirectory(prefix="rcbht-stops-") as tmp:
        t0 = time.monotonic()
        stops, sent = stop_loop(n_node, n_record, Path(tmp))
        figures = summarise(stops)
        gaps = sorted(match_gaps(int(os.environ.get("RCBHT_STOPS_MATCH", "20")), Path(tmp)))
    figures["new_subscriber_match_gap_s"] = {
        "n": len(gaps),
        "p50": round(gaps[len(gaps) // 2], 4),
        "p90": round(gaps[int(len(gaps) * 0.9)], 4),
        "max": round(gaps[-1], 4),
    }
    figures["traffic"] = {**sent, "rate_hz": RATE_HZ}
    figures["seconds"] = round(time.monotonic() - t0, 1)
    return figures

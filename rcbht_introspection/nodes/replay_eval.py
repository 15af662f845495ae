"""`rcbht replay-eval`: replay trial bags through segmenter_node and classifier_node and score them.

The two nodes run as separate processes over real DDS, isolated on a random ROS_DOMAIN_ID
(1..101) with localhost-only discovery (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and the
loopback Fast DDS profile config/fastdds_localhost.xml) and logs in a temporary ROS_LOG_DIR.
This process plays each bag with its recorded timing divided by `rate` and records /task_state,
the beliefs, the applied sub-task events and the words; the scores compare them with the truth
in the bag and with the offline run of the same stream and model (rcbht_introspection.live.offline).
"""

from __future__ import annotations

import contextlib
import os
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import yaml

import rcbht_introspection
from rcbht_introspection.config import config_path
from rcbht_introspection.errors import InputError
from rcbht_introspection.io.bags import (
    END_PHASE,
    PHASE_TOPIC,
    WRENCH_TYPE,
    bag_messages,
    decode_wrench,
    read_trial_bag,
    wrench_topic,
)
from rcbht_introspection.live import offline
from rcbht_introspection.nodes.params import (
    NODE_NAMES,
    ClassifierConfig,
    SegmenterConfig,
    word_topics,
)
from rcbht_introspection.taxonomy.words import LEVELS, Word


@dataclass(frozen=True)
class ReplayEvalOptions:
    """How to run a replay evaluation."""

    rate: float = 1.0
    mode: str = "boundary"
    profile: str = "reference"
    stream_profile: str = "reference"
    state_hold_s: float = 0.0
    """classifier_node's state_hold_s (how long a new /task_state must hold)."""
    startup_timeout: float = 60.0
    drain_timeout: float = 60.0
    domain_id: int | None = None
    log_dir: Path | None = None
    """Keep the node logs here (default: a temporary folder, removed afterwards)."""
    offline: bool = True
    """Also compute the offline references (words and verdicts)."""


DOMAIN_IDS = range(1, 102)
"""ROS_DOMAIN_IDs whose DDS ports stay below the Linux ephemeral range."""
_LEASES: dict[int, Any] = {}


def lease_domain() -> int:
    """A ROS_DOMAIN_ID that no other process of this machine holds, held until released.

    Each id is a lock file (flock) under the temp directory; the lock goes with the process,
    so a crashed holder frees its id. Tests, replays and benchmarks that run at the same time
    therefore never share a DDS domain.
    """
    import fcntl

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
def environment(values: dict[str, str]):
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


def segmenter_matches(node: Any) -> Callable[[], int]:
    """A function giving the subscribers the segmenter's writers matched on every word topic."""
    from diagnostic_msgs.msg import DiagnosticArray

    latest = [0]

    def on_status(msg: Any) -> None:
        for status in msg.status:
            if status.name == "segmenter_node: outputs":
                values = {kv.key: kv.value for kv in status.values}
                latest[0] = int(values.get("word subscribers matched", 0))

    node.create_subscription(DiagnosticArray, "/diagnostics", on_status, 10)
    return lambda: latest[0]


def node_command(module: str, *ros_args: str) -> list[str]:
    """Command line that starts node `module` as its own process (`python -m ...nodes NODE`)."""
    return [sys.executable, "-m", "rcbht_introspection.nodes", module, "--ros-args", *ros_args]


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
        return self.proc.poll() is None

    def tail(self, lines: int = 15) -> str:
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
        code = self.proc.poll()
        if code is None:
            self.interrupt()  # once: a second SIGINT is not a harder stop
            try:
                code = self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
                code = None
        self._log_file.close()
        return code


@dataclass
class Observations:
    """What the observer received, with wall-clock receive times (ns)."""

    states: list[tuple[int, str]] = field(default_factory=list)
    beliefs: list[tuple[int, Any, int, int]] = field(default_factory=list)
    """(wall ns received, Belief, trigger stamp ns, wall ns the classifier published it)"""
    words: dict[tuple[int, str, str], list[Word]] = field(default_factory=dict)
    """(stream id, arm, level) -> words in arrival order"""
    ends: dict[tuple[int, str, str], tuple[int, int]] = field(default_factory=dict)
    """(stream id, arm, level) -> (samples accepted, rejected) at end of stream"""
    triggers: dict[int, set[int]] = field(default_factory=dict)
    """stream id -> stamps of wrench samples that finalised words"""
    word_arrivals: list[tuple[int, int]] = field(default_factory=list)
    """(wall ns, stamp of the sample that finalised them) of each non-empty Words message"""
    origins: dict[int, int] = field(default_factory=dict)
    """stream id -> time origin (ns)"""
    phases: list[tuple[int, str, float, int, int]] = field(default_factory=list)
    """(wall ns, name, stream time, stream id, stamp of the sample it was applied at)"""


class Observer:
    """Subscribes the nodes' outputs in this process and records them.

    Callbacks only keep the raw CDR and the receive time: decoding waits for `convert`, between
    bags, so the observer's CPU during playback is small and the nodes under test keep theirs.
    """

    def __init__(
        self, node: Any, seg: SegmenterConfig, cls_cfg: ClassifierConfig, qos: Any
    ) -> None:
        from rcbht_interfaces.msg import Belief as BeliefMsg
        from rcbht_interfaces.msg import Phase as PhaseMsg
        from rcbht_interfaces.msg import Words as WordsMsg
        from std_msgs.msg import String

        self.obs = Observations()
        self.lock = threading.Lock()
        self.received: list[tuple[int, str, tuple[str, str], bytes]] = []
        """(wall ns, kind, (arm, level) of words, raw CDR) not yet decoded"""
        self.types = {"state": String, "belief": BeliefMsg, "phase": PhaseMsg, "words": WordsMsg}
        self.subs = [
            node.create_subscription(
                self.types[kind], topic, partial(self.on_message, kind, ("", "")), qos, raw=True
            )
            for kind, topic in (
                ("state", cls_cfg.state_topic),
                ("belief", cls_cfg.belief_topic),
                ("phase", seg.applied_phase_topic),
            )
        ]
        self.word_topics = word_topics(seg.words_namespace, seg.arms)
        for key, topic in self.word_topics.items():
            self.subs.append(
                node.create_subscription(
                    WordsMsg, topic, partial(self.on_message, "words", key), qos, raw=True
                )
            )

    def on_message(self, kind: str, key: tuple[str, str], raw: bytes) -> None:
        wall = time.time_ns()
        with self.lock:
            self.received.append((wall, kind, key, raw))

    def convert(self) -> None:
        """Decode what arrived since the last call into the observations."""
        from rclpy.serialization import deserialize_message

        from rcbht_introspection.nodes.conversions import belief_from_msg, msg_to_word, to_ns

        with self.lock:
            received, self.received = self.received, []
        for wall, kind, (arm, level), raw in received:
            msg = deserialize_message(raw, self.types[kind])
            with self.lock:
                obs = self.obs
                if kind == "state":
                    if not obs.states or obs.states[-1][1] != msg.data:
                        obs.states.append((wall, msg.data))
                elif kind == "belief":
                    obs.beliefs.append(
                        (
                            wall,
                            belief_from_msg(msg),
                            to_ns(msg.trigger_stamp),
                            to_ns(msg.header.stamp),
                        )
                    )
                elif kind == "phase":
                    obs.phases.append(
                        (wall, msg.name, msg.time, msg.stream_id, to_ns(msg.header.stamp))
                    )
                else:
                    sid = msg.stream_id
                    obs.origins[sid] = to_ns(msg.time_origin)
                    obs.words.setdefault((sid, arm, level), []).extend(
                        msg_to_word(w) for w in msg.words
                    )
                    if msg.words:
                        stamp = to_ns(msg.header.stamp)
                        obs.triggers.setdefault(sid, set()).add(stamp)
                        obs.word_arrivals.append((wall, stamp))
                    if msg.end_of_stream:
                        obs.ends[(sid, arm, level)] = (
                            int(msg.samples_accepted),
                            int(msg.samples_rejected),
                        )

    def ended(self, origin: int, arms: tuple[str, ...]) -> bool:
        self.convert()
        with self.lock:
            return all(
                (origin, arm, level) in self.obs.ends
                for arm in arms
                for level in ("primitives", "compositions", "behaviors")
            )

    def finals_since(self, index: int) -> list[tuple[int, Any, int]]:
        self.convert()
        with self.lock:
            return [b for b in self.obs.beliefs[index:] if b[1].final]


def _wait(
    condition: Any,
    timeout: float,
    procs: list[NodeProcess],
    what: str,
    progress: Callable[[], str] | None = None,
) -> None:
    """Poll `condition`; on a timeout or a dead node, raise with the node logs (and `progress`)."""
    deadline = time.monotonic() + timeout
    while not condition():
        for p in procs:
            if not p.alive():
                raise InputError(f"{p.name} exited (code {p.proc.returncode}):\n{p.tail()}")
        if time.monotonic() > deadline:
            logs = "\n".join(f"--- {p.name}\n{p.tail()}" for p in procs)
            got = f" ({progress()})" if progress is not None else ""
            raise InputError(f"timed out after {timeout:.0f} s waiting for {what}{got}\n{logs}")
        time.sleep(0.05)


def replay_eval(
    bags: list[Path], model_path: Path | None, options: ReplayEvalOptions
) -> dict[str, Any]:
    """Run the live pipeline on `bags` and return the scores (see module doc).

    Without a model (None) the classifier publishes "unknown"; latencies and drops still count.
    """
    if model_path is not None and not Path(model_path).is_file():
        raise InputError("no such model file", model_path)
    if options.rate <= 0:
        raise InputError(f"rate must be > 0, got {options.rate}", field="rate")
    trials = [read_trial_bag(b) for b in bags]
    arms = trials[0].arms
    for b, t in zip(bags, trials, strict=True):
        if t.arms != arms:
            raise InputError(f"arms {list(t.arms)} differ from the first bag's {list(arms)}", b)
    domain_id = options.domain_id or lease_domain()
    tmp = tempfile.TemporaryDirectory(prefix="rcbht-replay-")
    work = Path(options.log_dir) if options.log_dir else Path(tmp.name)
    work.mkdir(parents=True, exist_ok=True)
    env = ros_env(domain_id, work / "ros_log")
    seg = SegmenterConfig(
        arms=arms,
        wrench_topics=tuple(wrench_topic(a, arms) for a in arms),
        taxonomy_profile=options.profile,
    )
    cls_cfg = ClassifierConfig(
        model_file=str(Path(model_path).resolve()) if model_path else "",
        mode=options.mode,
        arms=arms,
    )
    seg_params = write_params(
        work / "segmenter.yaml",
        SegmenterConfig,
        {
            "arms": list(arms),
            "wrench_topics": list(seg.wrench_topics),
            "taxonomy_profile": options.profile,
            "stream_profile": options.stream_profile,
        },
    )
    cls_params = write_params(
        work / "classifier.yaml",
        ClassifierConfig,
        {
            "model_file": cls_cfg.model_file,
            "mode": options.mode,
            "arms": list(arms),
            "state_hold_s": options.state_hold_s,
        },
    )
    started = time.monotonic()
    result: dict[str, Any] = {}
    with environment(env):
        from rcbht_introspection.nodes.common import RosSession, qos_profile
        from rcbht_introspection.nodes.player import BagPlayer

        procs: list[NodeProcess] = []
        codes: dict[str, int | None] = {}
        try:
            procs.append(
                NodeProcess("segmenter_node", seg_params, env, work / "segmenter_node.log")
            )
            procs.append(
                NodeProcess("classifier_node", cls_params, env, work / "classifier_node.log")
            )
            with RosSession("rcbht_replay_eval", domain_id=domain_id) as ros:
                qos = qos_profile(seg.qos_depth, "reliable")
                observer = Observer(ros.node, seg, cls_cfg, qos)
                player = BagPlayer(ros.node, qos)
                all_messages = [list(bag_messages(b)) for b in bags]
                for msgs in all_messages:
                    player.prepare(msgs)
                needed = [wrench_topic(a, arms) for a in arms] + [PHASE_TOPIC]
                classifier_inputs = ["/" + t for t in observer.word_topics.values()] + [
                    "/" + seg.applied_phase_topic
                ]

                matched = segmenter_matches(ros.node)

                def ready() -> bool:
                    # the graph shows the classifier's readers before the segmenter's writers
                    # have matched them; words published in between would be lost, so the
                    # segmenter's own /diagnostics must count both readers (observer, classifier)
                    return (
                        all(player.publishers[t].get_subscription_count() > 0 for t in needed)
                        and all(s.get_publisher_count() > 0 for s in observer.subs)
                        and all(ros.node.count_subscribers(t) >= 2 for t in classifier_inputs)
                        and matched() >= 2
                    )

                _wait(ready, options.startup_timeout, procs, "the nodes to connect")
                result["startup_s"] = round(time.monotonic() - started, 2)
                per_bag = []
                for stream_id, (bag, trial, msgs) in enumerate(
                    zip(bags, trials, all_messages, strict=True)
                ):
                    per_bag.append(
                        _play_one(
                            bag, trial, msgs, stream_id, player, observer, procs, options, arms
                        )
                    )
        finally:
            for p in procs:  # both stop at once: a Ctrl-C of the harness ends within seconds
                p.interrupt()
            for p in procs:
                codes[p.name] = p.stop()
                if codes[p.name] != 0:  # the node log is in a temporary folder: keep its end
                    result.setdefault("shutdown_logs", {})[p.name] = p.tail(40)
            if not options.domain_id:
                release_domain(domain_id)  # its nodes are gone
    result.update(_score(per_bag, trials, model_path, options, arms))
    result.update(
        {
            "bags": [str(b) for b in bags],
            "rate": options.rate,
            "mode": options.mode,
            "profile": options.profile,
            "stream_profile": options.stream_profile,
            "model": str(model_path),
            "domain_id": domain_id,
            "exit_codes": codes,
            "clean_shutdown": all(c == 0 for c in codes.values()),
            "wall_s": round(time.monotonic() - started, 2),
        }
    )
    tmp.cleanup()
    return result


def _play_one(
    bag: Path,
    trial: Any,
    msgs: list[Any],
    stream_id: int,
    player: Any,
    observer: Observer,
    procs: list[NodeProcess],
    options: ReplayEvalOptions,
    arms: tuple[str, ...],
) -> dict[str, Any]:
    """Play one bag, wait until every verdict and end-of-stream arrived; return the raw record."""
    observer.convert()
    with observer.lock:
        w_index = len(observer.obs.word_arrivals)
        b_index = len(observer.obs.beliefs)
        s_index = len(observer.obs.states)
        initial_state = observer.obs.states[-1][1] if observer.obs.states else "unknown"
    pub_wall: dict[int, int] = {}
    pub_series: list[tuple[int, int]] = []
    published = 0
    origin = None

    def on_publish(m: Any, wall: int) -> None:
        nonlocal published, origin
        if m.msgtype == WRENCH_TYPE:
            stamp = decode_wrench(m.raw)[0]
            if origin is None:
                origin = stamp
            published += 1
            if stamp not in pub_wall:
                pub_wall[stamp] = wall
                pub_series.append((wall, stamp))

    t0 = time.monotonic()
    player.play(msgs, rate=options.rate, on_publish=on_publish)
    play_s = time.monotonic() - t0
    n_subtasks = sum(1 for m in msgs if m.topic == PHASE_TOPIC) - 1  # minus the end event
    if options.mode == "window":
        n_subtasks = 0  # window mode issues no sub-task verdicts
    _wait(
        lambda: (
            observer.ended(stream_id, arms) and len(observer.finals_since(b_index)) >= n_subtasks
        ),
        options.drain_timeout,
        procs,
        f"the verdicts of {bag.name}",
        lambda: (
            f"{len(observer.finals_since(b_index))}/{n_subtasks} verdicts, end of stream "
            f"{sorted(k[1:] for k in observer.obs.ends if k[0] == stream_id)}, "
            f"{published} wrench published; received {len(observer.obs.word_arrivals) - w_index} "
            f"word messages, {len(observer.obs.beliefs) - b_index} beliefs, "
            f"{len(observer.obs.states) - s_index} state changes, {len(observer.obs.phases)} events"
        ),
    )
    observer.convert()
    with observer.lock:
        beliefs = list(observer.obs.beliefs[b_index:])
        word_arrivals = list(observer.obs.word_arrivals[w_index:])
        states = list(observer.obs.states[s_index:])
        words = {
            (arm, level): list(observer.obs.words.get((stream_id, arm, level), []))
            for arm in arms
            for level in ("primitives", "compositions", "behaviors")
        }
        ends = {k[1:]: v for k, v in observer.obs.ends.items() if k[0] == stream_id}
        triggers = set(observer.obs.triggers.get(stream_id, set()))
        node_origin = observer.obs.origins.get(stream_id)
        event_stamps = {p[4] for p in observer.obs.phases if p[3] == stream_id}
    return {
        "bag": bag,
        "origin": origin,
        "node_origin": node_origin,
        "event_stamps": event_stamps,
        "published": published,
        "play_s": play_s,
        "pub_wall": pub_wall,
        "pub_series": pub_series,
        "beliefs": beliefs,
        "word_arrivals": word_arrivals,
        "states": states,
        "initial_state": initial_state,
        "words": words,
        "ends": ends,
        "triggers": triggers,
    }


def _score(
    per_bag: list[dict[str, Any]],
    trials: list[Any],
    model_path: Path | None,
    options: ReplayEvalOptions,
    arms: tuple[str, ...],
) -> dict[str, Any]:
    """Scores over all bags plus a per-bag record."""
    model = None
    factory = None
    if options.offline and model_path is not None:
        from rcbht_introspection.learn.model_file import load_model
        from rcbht_introspection.live.segmenter import arm_stream_factory

        model = load_model(model_path)
        factory = arm_stream_factory(options.profile, stream_profile=options.stream_profile)
    correct = total = 0
    verdicts_match = words_match = True
    dropped = rejected = 0
    latencies: list[int] = []
    word_latencies: list[int] = []
    received_latencies: list[int] = []
    event_latencies: list[int] = []
    time_acc: list[tuple[float, float]] = []
    state_changes = 0
    bags_out = []
    prev_accepted = dict.fromkeys(arms, 0)
    for rec, trial in zip(per_bag, trials, strict=True):
        truth = [s for s, _, _ in trial.subtask_bounds()]
        finals = [b for _, b, _, _ in rec["beliefs"] if b.final]
        verdicts = [b.subtask for b in finals]
        total += len(truth)
        correct += sum(1 for v, t in zip(verdicts, truth, strict=False) if v == t)
        # samples accepted by the segmenter for this bag (its counters are cumulative)
        accepted = {}
        for arm in arms:
            acc, rej = rec["ends"].get((arm, "primitives"), (prev_accepted[arm], 0))
            accepted[arm] = acc - prev_accepted[arm]
            prev_accepted[arm] = acc
            rejected = max(rejected, rej)
        bag_dropped = rec["published"] - sum(accepted.values())
        dropped += bag_dropped
        # latency: wrench sample that finalised words -> each belief those words caused
        # (words finalised by a sub-task or end event are the event's, not a sample's: the end
        # event waits for sample silence, so they are reported apart)
        for wall, b, trig, sent in rec["beliefs"]:
            if trig in rec["triggers"] and trig in rec["pub_wall"] and not b.final:
                if trig in rec["event_stamps"]:
                    event_latencies.append(sent - rec["pub_wall"][trig])
                    continue
                latencies.append(sent - rec["pub_wall"][trig])
                received_latencies.append(wall - rec["pub_wall"][trig])
        for wall, trig in rec["word_arrivals"]:
            if trig in rec["pub_wall"] and trig not in rec["event_stamps"]:
                word_latencies.append(wall - rec["pub_wall"][trig])
        # /task_state timeline on the stream clock (wall receive time -> data time)
        walls = np.asarray([w for w, _ in rec["pub_series"]], dtype=float)
        data_t = (np.asarray([s for _, s in rec["pub_series"]], dtype=float) - rec["origin"]) / 1e9
        changes = [(float(np.interp(w, walls, data_t)), s) for w, s in rec["states"]]
        acc_t = offline.time_accuracy(trial, changes, initial=rec["initial_state"])
        state_changes += len(changes)
        duration = float(trial.time[-1] - trial.time[0])
        time_acc.append((acc_t, duration))
        bag_out: dict[str, Any] = {
            "name": trial.name,
            "truth": truth,
            "truth_starts": [
                round(s - float(trial.time[0]), 6) for _, s, _ in trial.subtask_bounds()
            ],
            "duration": round(float(trial.time[-1] - trial.time[0]), 6),
            "verdicts": verdicts,
            "final_probabilities": [
                dict(zip(b.classes, b.probabilities, strict=True)) for b in finals
            ],
            "time_accuracy": round(acc_t, 4),
            "timeline": [(round(t, 3), s) for t, s in changes],
            "initial_state": rec["initial_state"],
            "published_wrench": rec["published"],
            "dropped_wrench": bag_dropped,
            "play_s": round(rec["play_s"], 2),
            "node_words": sum(len(v) for v in rec["words"].values()),
        }
        if options.offline and model is not None and factory is not None:
            off_words = offline.offline_stream_words(trial, factory, END_PHASE)
            mismatch = ""
            for arm in arms:
                for level in LEVELS:
                    node_seq = rec["words"][(arm, level.value + "s")]
                    off_seq = [w for w in off_words[arm] if w.level == level]
                    why = offline.first_word_mismatch(node_seq, off_seq)
                    if why and not mismatch:
                        mismatch = f"arm {arm} {level.value}: {why}"
            node_words = {
                arm: [w for lv in LEVELS for w in rec["words"][(arm, lv.value + "s")]]
                for arm in arms
            }
            off_verdicts = offline.offline_verdicts(model, trial, off_words)
            node_offline_verdicts = offline.offline_verdicts(model, trial, node_words)
            bag_out.update(
                {
                    "offline_words": sum(len(v) for v in off_words.values()),
                    "words_match_offline": not mismatch,
                    "words_mismatch": mismatch,
                    "offline_verdicts": off_verdicts,
                    "offline_verdicts_of_node_words": node_offline_verdicts,
                    "verdicts_match_offline": verdicts == off_verdicts,
                }
            )
            words_match &= not mismatch
            if options.mode == "boundary":
                verdicts_match &= verdicts == off_verdicts
        bags_out.append(bag_out)
    weight = sum(d for _, d in time_acc) or 1.0
    return {
        "subtask_accuracy": round(correct / total, 4)
        if total and options.mode == "boundary"
        else None,
        "subtasks": total,
        "subtasks_correct": correct,
        "verdicts_match_offline": verdicts_match
        if model is not None and options.mode == "boundary"
        else None,
        "time_accuracy": round(sum(a * d for a, d in time_acc) / weight, 4),
        "state_changes": state_changes,
        "dropped_wrench": dropped,
        "rejected_wrench": rejected,
        "words_match_offline": words_match if model is not None else None,
        "latency_ms": offline.percentiles_ms(latencies),
        "latency_received_ms": offline.percentiles_ms(received_latencies),
        "word_latency_ms": offline.percentiles_ms(word_latencies),
        "event_latency_ms": offline.percentiles_ms(event_latencies),
        "per_bag": bags_out,
    }


def summary(result: dict[str, Any], timeline: bool = False) -> str:
    """Human-readable report of a replay-eval result."""
    lines = []
    for b in result["per_bag"]:
        lines.append(f"{b['name']}: truth {b['truth']}")
        lines.append(f"  verdicts {b['verdicts']}  (offline {b.get('offline_verdicts')})")
        if timeline:
            truth = ", ".join(
                f"{t:.2f}s {s}" for t, s in zip(b["truth_starts"], b["truth"], strict=True)
            )
            lines.append(f"  truth:       {truth}, end {b['duration']:.2f}s")
            steps = ", ".join(f"{t:.2f}s {s}" for t, s in b["timeline"])
            lines.append(f"  /task_state: start {b['initial_state']}, {steps}")
    lat = result["latency_ms"]
    lines.append(
        f"subtask_accuracy {result['subtask_accuracy']} ({result['subtasks_correct']}/{result['subtasks']}), "
        f"time_accuracy {result['time_accuracy']}, verdicts_match_offline {result['verdicts_match_offline']}, "
        f"words_match_offline {result['words_match_offline']}, dropped_wrench {result['dropped_wrench']}, "
        f"latency p50 {lat['p50']} ms p99 {lat['p99']} ms (n={lat['n']}), "
        f"clean_shutdown {result['clean_shutdown']}, rate {result['rate']}x, {result['wall_s']} s"
    )
    return "\n".join(lines)

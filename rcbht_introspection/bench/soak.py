"""Soak benchmark: an hour of 2 x 1 kHz wrench through segmenter_node and classifier_node.

`make soak` (or `python -m rcbht_introspection.bench --only soak`; `make bench` skips it). The
two nodes run as separate processes over real DDS, set up as `rcbht replay-eval` does (private
random ROS_DOMAIN_ID, localhost-only discovery, logs in bench_out/soak/). This process publishes
two-arm trials one after another, each with its /task_phase sub-task events and the end event,
re-stamped so that every arm's stamps keep going forward; the classifier is stopped with SIGINT
and started again at RCBHT_SOAK_RESTART_AT of the run while the wrench keeps flowing.

Trials: REAL HIRO trials (200 Hz played at 5x = 1 kHz; arm R from one trial, arm L from the next)
when ../shared data is present, with the ROS benchmark's model (`rcbht train` default on trials
1-40); else two-arm trials of the project's simulator (200 Hz at 5x too), without a model. As in
the ROS benchmark, stream time runs at 5x the wall clock: five times the words and verdicts per
second of a real-time 1 kHz sensor, the heavier load for the classifier.

Figures: wrench published per arm against the samples the segmenter accepted (Words counters),
verdicts per classifier process, RSS and CPU of each node process every RCBHT_SOAK_SAMPLE_S, the
RSS growth over the last 30 minutes (the last half of shorter runs), and every exit code.

Environment: RCBHT_SOAK_SECONDS (default 3600), RCBHT_SOAK_SAMPLE_S (60),
RCBHT_SOAK_RESTART_AT (fraction of the run, 0.25: the new classifier is then well past its
start-up when the last 30 minutes begin), RCBHT_SOAK_MODEL (a model file: skip training).
"""

from __future__ import annotations

import functools
import json
import os
import shutil
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.hiro import find_trials, read_trial, shared_hiro
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.replay.supervision import (
    NodeProcess,
    environment,
    lease_domain,
    ros_env,
    wait_for_nodes,
    write_params,
)
from rcbht_introspection.waiting import wait_until

ARMS: tuple[str, ...] = ("L", "R")
GROWTH_WINDOW_S = 1800.0
"""RSS growth is measured over the last 30 minutes (the last half of a shorter run)."""
TRIAL_GAP_S = 0.5
"""Pause between trials (the end event is applied after 0.2 s without samples)."""
SIM_TRIALS = 6
"""Distinct simulated trials played in turn when there is no HIRO data."""
STARTUP_TIMEOUT_S = 60.0
DRAIN_TIMEOUT_S = 60.0
LATE_MS = 10.0
"""A sample published this much after its due time counts as late (publisher, not nodes)."""


def env_float(name: str, default: float) -> float:
    """A positive float from the environment (`default` when unset)."""
    text = os.environ.get(name, "").strip()
    if not text:
        return default
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{name} must be a number, got {text!r}") from None
    if value <= 0:
        raise InputError(f"{name} must be > 0, got {value}")
    return value


# --- trials --------------------------------------------------------------------------------


@dataclass(frozen=True)
class Source:
    """Where the trials come from: `trial(i)` is the i-th two-arm trial, played at `rate`."""

    name: str
    rate: float
    trial: Callable[[int], Trial]


def trial_source() -> Source:
    """REAL HIRO trials when present, else the simulator's two-arm trials; both at 5x."""
    from rcbht_introspection.bench import ros

    hiro = shared_hiro()
    if hiro is not None:
        folders = find_trials([hiro])
        order = [folders[(40 + i) % len(folders)] for i in range(len(folders))]  # held out first
        read = functools.lru_cache(maxsize=len(order))(lambda k: read_trial(order[k]))

        def real(i: int) -> Trial:
            k = i % len(order)
            return ros.two_arm_trial(read(k), read((k + 1) % len(order)))

        return Source(
            f"REAL HIRO trials at 5x ({hiro})", ros.TARGET_RATE_HZ / ros.SOURCE_RATE_HZ, real
        )
    from rcbht_introspection.sim import load_sim_config, simulate_trial

    config = load_sim_config()
    sims = [
        simulate_trial(config, 1000 + k, "two-arm", rate_hz=ros.SOURCE_RATE_HZ)
        for k in range(SIM_TRIALS)
    ]
    return Source(
        "simulator, two-arm trials, 200 Hz at 5x",
        ros.TARGET_RATE_HZ / ros.SOURCE_RATE_HZ,
        lambda i: sims[i % SIM_TRIALS],
    )


@dataclass
class Playback:
    """One trial ready to publish: per sample its due offset (s), raw wrench per arm, events."""

    name: str
    offsets: np.ndarray
    raws: list[list[bytes]]
    """raws[i]: the wrench messages of sample i, in ARMS order"""
    events: dict[int, list[str]]
    """sample index -> /task_phase names published right after it"""
    last_stamp_ns: int


def playback(trial: Trial, base_ns: int, rate: float) -> Playback:
    """Trial re-stamped to start at `base_ns`; events placed as write_trial_bag places them."""
    from rcbht_introspection.io.bags import encode_wrench, trial_phase_events

    t_ns = np.rint((np.asarray(trial.time, dtype=np.float64) - trial.time[0]) * 1e9).astype(
        np.int64
    )
    stamps = base_ns + t_ns
    wrench = [trial.wrench[arm].tolist() for arm in ARMS]
    raws = [
        [encode_wrench(int(s), arm, wrench[a][i]) for a, arm in enumerate(ARMS)]
        for i, s in enumerate(stamps.tolist())
    ]
    # an event follows the last sample before it (a sample at its exact time comes first)
    events: dict[int, list[str]] = {}
    for when, name in trial_phase_events(trial):
        e_ns = round((when - float(trial.time[0])) * 1e9)
        i = max(int(np.searchsorted(t_ns, e_ns, side="right")) - 1, 0)
        events.setdefault(i, []).append(name)
    return Playback(trial.name, t_ns / 1e9 / rate, raws, events, int(stamps[-1]))


# --- the publisher -------------------------------------------------------------------------


@dataclass
class PublisherStats:
    """What the publisher thread did (read by the main thread)."""

    published: dict[str, int] = field(default_factory=lambda: dict.fromkeys(ARMS, 0))
    """per arm, samples of the trials finished so far"""
    in_trial: int = 0
    """samples per arm published of the trial under way"""
    subtask_events: int = 0
    end_events: int = 0
    trials: list[dict[str, Any]] = field(default_factory=list)
    """per trial: index, name, start/end wall ns, samples, sub-task events, cut"""
    play_s: float = 0.0
    late: int = 0
    max_late_ms: float = 0.0
    error: str | None = None
    done: bool = False


class SoakPublisher(threading.Thread):
    """Publishes trial after trial until `deadline` (a cut trial still gets its end event)."""

    def __init__(self, node: Any, qos: Any, source: Source, seconds: float) -> None:
        super().__init__(name="soak-publisher", daemon=True)
        from geometry_msgs.msg import WrenchStamped
        from std_msgs.msg import String

        from rcbht_introspection.io.bags import PHASE_TOPIC, wrench_topic

        self.source = source
        self.seconds = seconds
        self.String = String
        self.wrench_pubs = [
            node.create_publisher(WrenchStamped, wrench_topic(arm, ARMS), qos) for arm in ARMS
        ]
        self.phase_pub = node.create_publisher(String, PHASE_TOPIC, qos)
        self.stats = PublisherStats()
        self.stop_event = threading.Event()

    def matched(self) -> bool:
        """Every input topic of the segmenter has a subscriber."""
        return all(p.get_subscription_count() > 0 for p in (*self.wrench_pubs, self.phase_pub))

    def run(self) -> None:
        from rcbht_introspection.io.bags import END_PHASE

        stats = self.stats
        deadline = time.perf_counter() + self.seconds
        base_ns = time.time_ns()
        i = 0
        try:
            while not self.stop_event.is_set() and time.perf_counter() < deadline:
                pb = playback(self.source.trial(i), base_ns, self.source.rate)
                base_ns = pb.last_stamp_ns + int(TRIAL_GAP_S * self.source.rate * 1e9)
                record = self._play(i, pb, deadline)
                if record["samples_per_arm"] == 0:
                    break  # cut before its first sample: there is no stream to end
                if record["cut"]:  # the end event the cut left out
                    self.phase_pub.publish(self.String(data=END_PHASE))
                stats.end_events += 1
                stats.trials.append(record)
                i += 1
                if time.perf_counter() < deadline:
                    self.stop_event.wait(TRIAL_GAP_S)
        except Exception as exc:  # reported in the results, never a silent end
            stats.error = f"{type(exc).__name__}: {exc}"
        finally:
            stats.done = True

    def _play(self, index: int, pb: Playback, deadline: float) -> dict[str, Any]:
        """Publish one trial at its recorded spacing / rate; stop early at `deadline`."""
        stats = self.stats
        pubs = self.wrench_pubs
        stop = self.stop_event
        perf = time.perf_counter
        t0 = perf()
        start_wall = time.time_ns()
        subtasks = 0
        n = 0
        cut = False
        for i, offset in enumerate(pb.offsets.tolist()):
            now = perf()
            if now >= deadline or stop.is_set():
                cut = True
                break
            delay = t0 + offset - now
            if delay > 0:
                time.sleep(delay)
            elif -delay * 1e3 > LATE_MS:
                stats.late += 1
                stats.max_late_ms = max(stats.max_late_ms, -delay * 1e3)
            for pub, raw in zip(pubs, pb.raws[i], strict=True):
                pub.publish(raw)
            n += 1
            stats.in_trial = n
            for name in pb.events.get(i, ()):
                self.phase_pub.publish(self.String(data=name))
                if name in _subtask_names():
                    subtasks += 1
        play_s = perf() - t0
        for arm in ARMS:
            stats.published[arm] += n
        stats.in_trial = 0
        stats.subtask_events += subtasks
        stats.play_s += play_s
        return {
            "index": index,
            "name": pb.name,
            "start_wall_ns": start_wall,
            "end_wall_ns": time.time_ns(),
            "samples_per_arm": n,
            "subtask_events": subtasks,
            "cut": cut,
        }


@functools.cache
def _subtask_names() -> frozenset[str]:
    from rcbht_introspection.io.trial import SUBTASKS

    return frozenset(SUBTASKS)


# --- the observer --------------------------------------------------------------------------


class SoakObserver:
    """Counts what the nodes publish: segmenter counters, applied events, beliefs and verdicts.

    Beliefs are binned by their header stamp (the classifier's wall clock when it computed them)
    against `split_ns`, the moment the first classifier exited: bin 0 before, bin 1 after.
    """

    def __init__(self, node: Any, qos: Any) -> None:
        from rcbht_interfaces.msg import Belief as BeliefMsg
        from rcbht_interfaces.msg import Phase as PhaseMsg
        from rcbht_interfaces.msg import Words as WordsMsg

        from rcbht_introspection.nodes.params import ClassifierConfig, SegmenterConfig, word_topics
        from rcbht_introspection.replay.observer import segmenter_matches

        seg, cls_cfg = SegmenterConfig(), ClassifierConfig()
        self.lock = threading.Lock()
        self.accepted = dict.fromkeys(ARMS, 0)
        self.rejected = dict.fromkeys(ARMS, 0)
        self.streams_ended = dict.fromkeys(ARMS, 0)
        self.applied = {"subtask": 0, "end": 0}
        self.beliefs = [0, 0]
        self.verdicts = [0, 0]
        self.split_ns: int | None = None
        self.word_topics = word_topics(seg.words_namespace, ARMS)
        self.applied_topic = seg.applied_phase_topic
        self.belief_sub = node.create_subscription(
            BeliefMsg, cls_cfg.belief_topic, self.on_belief, qos
        )
        self.subs = [self.belief_sub]
        # every word topic, so that the segmenter's own count of matched word readers (its
        # /diagnostics) reaches 2 only once the classifier's are matched too
        for (arm, level), topic in self.word_topics.items():
            on_words = functools.partial(self.on_words, arm, level == "primitives")
            self.subs.append(node.create_subscription(WordsMsg, topic, on_words, qos))
        self.subs.append(node.create_subscription(PhaseMsg, self.applied_topic, self.on_phase, qos))
        self.segmenter_matched = segmenter_matches(node)

    def on_belief(self, msg: Any) -> None:
        stamp = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
        with self.lock:
            b = 0 if self.split_ns is None or stamp < self.split_ns else 1
            self.beliefs[b] += 1
            if msg.final:
                self.verdicts[b] += 1

    def on_words(self, arm: str, counted: bool, msg: Any) -> None:
        if not counted:
            return  # the same counters come on the primitives topic
        with self.lock:
            self.accepted[arm] = max(self.accepted[arm], int(msg.samples_accepted))
            self.rejected[arm] = max(self.rejected[arm], int(msg.samples_rejected))
            if msg.end_of_stream:
                self.streams_ended[arm] += 1

    def on_phase(self, msg: Any) -> None:
        with self.lock:
            self.applied["end" if msg.name not in _subtask_names() else "subtask"] += 1

    def connected(self, node: Any) -> bool:
        """The nodes publish what this observes, and the segmenter's writers matched both the
        classifier's readers and this observer's (the graph lists readers before that)."""
        if not all(s.get_publisher_count() > 0 for s in self.subs):
            return False
        topics = [*self.word_topics.values(), self.applied_topic]
        return (
            all(node.count_subscribers("/" + t) >= 2 for t in topics)
            and self.segmenter_matched() >= 2
        )


# --- processes -----------------------------------------------------------------------------


def proc_status(pid: int) -> tuple[float, float] | None:
    """(RSS MiB, CPU seconds user+system) of a live process from /proc, None when it is gone."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    rss_kib = 0
    for line in status.splitlines():
        if line.startswith("VmRSS:"):
            rss_kib = int(line.split()[1])
            break
    fields = stat.rsplit(")", 1)[1].split()
    ticks = int(fields[11]) + int(fields[12])  # utime, stime (fields 14 and 15 of stat)
    return rss_kib / 1024.0, ticks / os.sysconf("SC_CLK_TCK")


@dataclass
class Tracked:
    """One sampled process: its RSS/CPU series (seconds since the soak started) and its end."""

    name: str
    pid: int
    started_s: float
    samples: list[tuple[float, float, float]] = field(default_factory=list)
    """(t s, RSS MiB, CPU s)"""
    exit_code: int | None = None
    stopped: bool = False
    stop_s: float | None = None
    ended_s: float | None = None

    def sample(self, t: float) -> None:
        got = proc_status(self.pid)
        if got is not None:
            self.samples.append((round(t, 2), round(got[0], 2), round(got[1], 2)))


def growth(samples: list[tuple[float, float, float]], window_s: float) -> dict[str, Any]:
    """RSS growth (percent) from the sample nearest `window_s` before the last one to the last."""
    if len(samples) < 2:
        return {"window_s": window_s, "growth_pct": None, "max_growth_pct": None}
    end = samples[-1][0]
    start = min(range(len(samples) - 1), key=lambda i: abs(samples[i][0] - (end - window_s)))
    inside = samples[start:]
    first = inside[0][1]
    return {
        "window_s": round(end - inside[0][0], 1),
        "growth_pct": round(100.0 * (inside[-1][1] - first) / first, 2) if first else None,
        "max_growth_pct": round(100.0 * (max(s[1] for s in inside) - first) / first, 2)
        if first
        else None,
    }


def process_figures(p: Tracked, run_end_s: float, window_s: float) -> dict[str, Any]:
    """RSS series and its growth (the run's last window if the process lived through it, else
    the last half of its own life), CPU, exit code."""
    s = p.samples
    lived = (s[-1][0] - s[0][0]) if s else 0.0
    covers = bool(s) and s[0][0] <= run_end_s - window_s + 1e-6 and s[-1][0] >= run_end_s - 1.0
    out: dict[str, Any] = {
        "pid": p.pid,
        "started_s": round(p.started_s, 1),
        "ended_s": round(p.ended_s, 1) if p.ended_s is not None else None,
        "rss_mib": [[t, rss] for t, rss, _ in s],
        "rss_start_mib": s[0][1] if s else None,
        "rss_end_mib": s[-1][1] if s else None,
        "rss_peak_mib": max(x[1] for x in s) if s else None,
        "cpu_s": s[-1][2] if s else None,
        "cpu_pct": round(100.0 * (s[-1][2] - s[0][2]) / lived, 1) if lived > 0 else None,
        "growth_over": "last window of the run" if covers else "last half of its life",
        **growth(s, window_s if covers else lived / 2),
        "exit_code": p.exit_code,
        "stop_s": p.stop_s,
    }
    return out


def _stop(node: Any, tracked: Tracked, t: float) -> None:
    """SIGINT one node process; record its exit code and how long it took to exit."""
    if not tracked.samples or t - tracked.samples[-1][0] > 1.0:
        tracked.sample(t)
    t0 = time.monotonic()
    tracked.exit_code = node.stop()
    tracked.stop_s = round(time.monotonic() - t0, 2)
    tracked.stopped = True
    tracked.ended_s = t + tracked.stop_s


# --- the run -------------------------------------------------------------------------------


def run(out_dir: Path) -> dict[str, Any]:
    """The soak; returns its figures (and prints a summary). Progress: out_dir/soak/progress.json."""
    from rcbht_introspection.bench import ros
    from rcbht_introspection.bench.__main__ import machine
    from rcbht_introspection.nodes.params import ClassifierConfig, SegmenterConfig

    seconds = env_float("RCBHT_SOAK_SECONDS", 3600.0)
    sample_s = env_float("RCBHT_SOAK_SAMPLE_S", 60.0)
    restart_at = env_float("RCBHT_SOAK_RESTART_AT", 0.25)
    if restart_at >= 1:
        raise InputError(f"RCBHT_SOAK_RESTART_AT must be in (0, 1), got {restart_at}")
    work = Path(out_dir) / "soak"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    wall0 = time.monotonic()
    source = trial_source()
    model_env = os.environ.get("RCBHT_SOAK_MODEL", "")
    model = Path(model_env) if model_env else ros._model(work)
    if model is not None and not model.is_file():
        raise InputError("no such model file", model)
    domain_id = lease_domain()  # held for the whole run
    env = ros_env(domain_id, work / "ros_log")
    seg_params = write_params(
        work / "segmenter.yaml",
        SegmenterConfig,
        {"arms": list(ARMS), "wrench_topics": [f"/{arm}/wrench" for arm in ARMS]},
    )
    cls_params = write_params(
        work / "classifier.yaml",
        ClassifierConfig,
        {
            "model_file": str(model.resolve()) if model else "",
            "mode": "boundary",
            "arms": list(ARMS),
        },
    )
    result: dict[str, Any] = {
        "duration_s_target": seconds,
        "sample_s": sample_s,
        "source": source.name,
        "playback_rate_x": source.rate,
        "arms": list(ARMS),
        "model": str(model) if model else None,
        "domain_id": domain_id,
        "machine": machine(),
        "aborted": None,
    }
    load: list[list[float]] = []
    tracked: list[Tracked] = []
    nodes: dict[str, Any] = {}
    restart: dict[str, Any] = {}
    t_start = time.monotonic()
    publisher: SoakPublisher | None = None
    observer: SoakObserver | None = None

    # this process (publisher and observer) is sampled too, for reference
    tracked_self = Tracked("soak_driver", os.getpid(), 0.0)

    def now() -> float:
        return time.monotonic() - t_start

    def start(module: str, name: str) -> None:
        params = seg_params if module == "segmenter_node" else cls_params
        node = NodeProcess(module, params, env, work / f"{name}.log")
        node.name = name
        nodes[name] = node
        tracked.append(Tracked(name, node.proc.pid, now()))

    def sample_all() -> None:
        t = now()
        for p in tracked:
            if not p.stopped:
                p.sample(t)
        tracked_self.sample(t)
        load.append([round(t, 1), *(round(x, 2) for x in os.getloadavg())])

    def progress() -> dict[str, Any]:
        assert publisher is not None and observer is not None
        st = publisher.stats
        with observer.lock:
            counts = {
                "accepted": dict(observer.accepted),
                "rejected": dict(observer.rejected),
                "streams_ended": dict(observer.streams_ended),
                "applied_events": dict(observer.applied),
                "beliefs": list(observer.beliefs),
                "verdicts": list(observer.verdicts),
            }
        return {
            "t_s": round(now(), 1),
            "published": {a: n + st.in_trial for a, n in st.published.items()},
            "trials": len(st.trials),
            **counts,
            "rss_mib": {p.name: p.samples[-1][1] for p in tracked if p.samples},
            "load_avg": load[-1][1:] if load else None,
        }

    result["load_avg_before"] = [round(x, 2) for x in os.getloadavg()]
    with environment(env):
        from rcbht_introspection.nodes.common import RosSession, qos_profile

        start("segmenter_node", "segmenter_node")
        start("classifier_node", "classifier_node_1")
        try:
            with RosSession("rcbht_soak", domain_id=domain_id) as session:
                qos = qos_profile(SegmenterConfig().qos_depth, "reliable")
                observer = SoakObserver(session.node, qos)
                publisher = SoakPublisher(session.node, qos, source, seconds)
                result["startup_s"] = round(
                    wait_for_nodes(
                        lambda: publisher.matched() and observer.connected(session.node),
                        STARTUP_TIMEOUT_S,
                        list(nodes.values()),
                        "the nodes to connect",
                    ),
                    2,
                )
                t_start = time.monotonic()
                for p in tracked:
                    p.started_s = 0.0
                publisher.start()
                next_sample = 0.0
                restart_s = restart_at * seconds
                while not publisher.stats.done:
                    t = now()
                    if not restart and t >= restart_s:
                        restart.update(_restart(nodes, tracked, observer, session.node, now, start))
                        if now() < next_sample:  # else the periodic sample right below
                            sample_all()
                    if t >= next_sample:
                        sample_all()
                        next_sample += sample_s
                        (work / "progress.json").write_text(json.dumps(progress(), indent=1))
                        print(f"soak {json.dumps(progress())}", flush=True)
                    dead = [
                        (n, node)
                        for n, node in nodes.items()
                        if not node.alive() and not _by_name(tracked, n).stopped
                    ]
                    if dead:
                        name, node = dead[0]
                        result["aborted"] = (
                            f"{name} exited (code {node.proc.returncode}) at {t:.0f} s"
                        )
                        result["aborted_log_tail"] = node.tail(40)
                        break
                    time.sleep(min(0.2, max(0.01, next_sample - now())))
                publisher.stop_event.set()
                publisher.join(30.0)
                published_end = now()
                st = publisher.stats
                if result["aborted"] is None:

                    def drained() -> bool:
                        with observer.lock:
                            return observer.applied["end"] >= st.end_events and all(
                                observer.streams_ended[a] >= st.end_events
                                and observer.accepted[a] + observer.rejected[a] >= st.published[a]
                                for a in ARMS
                            )

                    running = [
                        n for name, n in nodes.items() if not _by_name(tracked, name).stopped
                    ]
                    try:
                        result["drain_s"] = round(
                            wait_for_nodes(drained, DRAIN_TIMEOUT_S, running, "the drain"), 2
                        )
                    except InputError as exc:
                        result["aborted"] = f"drain: {str(exc).splitlines()[0]}"
                        result["aborted_log_tail"] = str(exc)
                sample_all()
                result["publish_s"] = round(published_end, 1)
        except InputError as exc:
            result["aborted"] = str(exc).splitlines()[0]
            result["aborted_log_tail"] = str(exc)
        finally:
            if publisher is not None:
                publisher.stop_event.set()
            t_end = now()
            # downstream first: the classifier, then the segmenter
            for name in sorted(nodes, key=lambda n: n.startswith("segmenter")):
                p = _by_name(tracked, name)
                if not p.stopped:
                    _stop(nodes[name], p, t_end)
                    if p.exit_code != 0:
                        result.setdefault("shutdown_logs", {})[name] = nodes[name].tail(40)
    result["load_avg_after"] = [round(x, 2) for x in os.getloadavg()]
    if publisher is None or observer is None:
        result["wall_s"] = round(time.monotonic() - wall0, 1)
        return result
    result.update(_figures(publisher, observer, tracked, tracked_self, restart, load))
    result["wall_s"] = round(time.monotonic() - wall0, 1)
    print(summary(result), flush=True)
    return result


def _by_name(tracked: list[Tracked], name: str) -> Tracked:
    return next(p for p in tracked if p.name == name)


def _restart(
    nodes: dict[str, Any],
    tracked: list[Tracked],
    observer: SoakObserver,
    node: Any,
    now: Callable[[], float],
    start: Callable[[str, str], None],
) -> dict[str, Any]:
    """SIGINT the running classifier, start a new one, wait until it is connected."""
    t = now()
    old = _by_name(tracked, "classifier_node_1")
    _stop(nodes[old.name], old, t)
    with observer.lock:
        observer.split_ns = time.time_ns()
    # the next belief publisher must be the new process, not the old one still in the graph,
    # and the segmenter's matched-reader count (1 Hz /diagnostics) must have seen it leave
    t0 = time.monotonic()
    left = wait_until(
        lambda: observer.belief_sub.get_publisher_count() == 0 and observer.segmenter_matched() < 2,
        10.0,
    )
    gone = time.monotonic() - t0 if left else None
    start("classifier_node", "classifier_node_2")
    new = nodes["classifier_node_2"]
    try:
        ready = wait_for_nodes(
            lambda: observer.connected(node), STARTUP_TIMEOUT_S, [new], "new classifier"
        )
    except InputError as exc:
        return {"at_s": round(t, 1), "exit_code": old.exit_code, "error": str(exc)}
    return {
        "at_s": round(t, 1),
        "ready_wall_ns": time.time_ns(),
        "exit_code": old.exit_code,
        "stop_s": old.stop_s,
        "old_left_graph_s": round(gone, 2) if gone is not None else None,
        "new_ready_s": round(ready, 2),
        "gap_s": round(now() - t, 2),
    }


def _figures(
    publisher: SoakPublisher,
    observer: SoakObserver,
    tracked: list[Tracked],
    tracked_self: Tracked,
    restart: dict[str, Any],
    load: list[list[float]],
) -> dict[str, Any]:
    """The soak's figures from the publisher's, the observer's and the sampler's records."""
    st = publisher.stats
    with observer.lock:
        accepted = dict(observer.accepted)
        rejected = dict(observer.rejected)
        ended = dict(observer.streams_ended)
        applied = dict(observer.applied)
        beliefs = list(observer.beliefs)
        verdicts = list(observer.verdicts)
    run_end = max((s[-1][0] for p in tracked if (s := p.samples)), default=0.0)
    window = min(GROWTH_WINDOW_S, run_end / 2)
    processes = {p.name: process_figures(p, run_end, window) for p in tracked}
    processes[tracked_self.name] = process_figures(tracked_self, run_end, window)
    exit_codes = {p.name: p.exit_code for p in tracked}
    return {
        "duration_s": round(st.play_s, 1),
        "trials": len(st.trials),
        "trials_cut": sum(1 for r in st.trials if r["cut"]),
        "wrench_published": dict(st.published),
        "wrench_accepted": accepted,
        "wrench_rejected": rejected,
        "wrench_dropped": sum(st.published[a] - accepted[a] for a in ARMS),
        "achieved_rate_hz_per_arm": {
            a: round(st.published[a] / st.play_s, 1) if st.play_s else None for a in ARMS
        },
        "publisher_late_samples": st.late,
        "publisher_max_late_ms": round(st.max_late_ms, 2),
        "publisher_error": st.error,
        "subtask_events_published": st.subtask_events,
        "end_events_published": st.end_events,
        "events_applied": applied,
        "streams_ended": ended,
        "beliefs": {"classifier_node_1": beliefs[0], "classifier_node_2": beliefs[1]},
        "verdicts": {"classifier_node_1": verdicts[0], "classifier_node_2": verdicts[1]},
        "subtask_events_after_restart": sum(
            r["subtask_events"]
            for r in st.trials
            if r["start_wall_ns"] >= restart.get("ready_wall_ns", time.time_ns())
        ),
        "restart": {k: v for k, v in restart.items() if k != "ready_wall_ns"},
        "exit_codes": exit_codes,
        "unclean_exits": sum(1 for c in exit_codes.values() if c != 0),
        "growth_window_s": round(window, 1),
        "rss_bounded_5pct": {
            name: (f["growth_pct"] is not None and f["growth_pct"] < 5.0)
            for name, f in processes.items()
            if name != tracked_self.name
        },
        "processes": processes,
        "load_avg_series": load,
    }


def summary(r: dict[str, Any]) -> str:
    """A short table of the soak's figures."""
    lines = [
        f"soak {r.get('duration_s')} s of {r['source']}: {r.get('trials')} trials, "
        f"published {r.get('wrench_published')}, dropped {r.get('wrench_dropped')}, "
        f"rate {r.get('achieved_rate_hz_per_arm')} Hz/arm, verdicts {r.get('verdicts')}, "
        f"unclean exits {r.get('unclean_exits')}, aborted {r['aborted']}",
        f"{'process':<20}{'RSS start':>10}{'end':>8}{'peak':>8}{'growth %':>10}"
        f"{'over s':>8}{'CPU %':>7}{'exit':>6}",
    ]
    for name, p in r.get("processes", {}).items():
        lines.append(
            f"{name:<20}{_fmt(p['rss_start_mib']):>10}{_fmt(p['rss_end_mib']):>8}"
            f"{_fmt(p['rss_peak_mib']):>8}{_fmt(p['growth_pct']):>10}{_fmt(p['window_s']):>8}"
            f"{_fmt(p['cpu_pct']):>7}{_fmt(p['exit_code']):>6}"
        )
    return "\n".join(lines)


def _fmt(value: object) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.1f}"
    return str(value)

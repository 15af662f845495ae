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

import json
import os
import shutil
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rcbht_introspection.bench import ros
from rcbht_introspection.bench.machine import machine
from rcbht_introspection.bench.process_watch import Tracked, process_figures
from rcbht_introspection.bench.soak_traffic import (
    ARMS,
    SoakObserver,
    SoakPublisher,
    Source,
    trial_source,
)
from rcbht_introspection.configure.params import ClassifierConfig, SegmenterConfig
from rcbht_introspection.errors import InputError
from rcbht_introspection.nodes.common import qos_profile
from rcbht_introspection.replay.supervision import (
    NodeProcess,
    environment,
    lease_domain,
    ros_env,
    wait_for_nodes,
    write_params,
)
from rcbht_introspection.rostools.session import RosSession
from rcbht_introspection.waiting import wait_until

GROWTH_WINDOW_S = 1800.0
"""RSS growth is measured over the last 30 minutes (the last half of a shorter run)."""
STARTUP_TIMEOUT_S = 60.0
DRAIN_TIMEOUT_S = 60.0


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
    model = ros.model_from_env("RCBHT_SOAK_MODEL", work)
    domain_id = lease_domain()  # held for the whole run
    env = ros_env(domain_id, work / "ros_log")
    seg_params, cls_params = _node_params(work, model)
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
    soak = _Soak(work, env, seg_params, cls_params)
    result["load_avg_before"] = [round(x, 2) for x in os.getloadavg()]
    with environment(env):
        soak.start("segmenter_node", "segmenter_node")
        soak.start("classifier_node", "classifier_node_1")
        try:
            with RosSession("rcbht_soak", domain_id=domain_id) as session:
                soak.play(session, source, seconds, sample_s, restart_at, result)
        except InputError as exc:
            result["aborted"] = str(exc).splitlines()[0]
            result["aborted_log_tail"] = str(exc)
        finally:
            soak.stop_nodes(result)
    result["load_avg_after"] = [round(x, 2) for x in os.getloadavg()]
    if soak.publisher is None or soak.observer is None:
        result["wall_s"] = round(time.monotonic() - wall0, 1)
        return result
    result.update(
        _figures(
            soak.publisher, soak.observer, soak.tracked, soak.tracked_self, soak.restart, soak.load
        )
    )
    result["wall_s"] = round(time.monotonic() - wall0, 1)
    print(summary(result), flush=True)
    return result


def _node_params(work: Path, model: Path | None) -> tuple[Path, Path]:
    """The parameter files of segmenter_node and classifier_node (two arms, boundary mode)."""
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
    return seg_params, cls_params


class _Soak:
    """One soak run's state: the node processes, their samples, the publisher and observer."""

    def __init__(self, work: Path, env: dict[str, str], seg_params: Path, cls_params: Path) -> None:
        self.work = work
        self.env = env
        self.seg_params = seg_params
        self.cls_params = cls_params
        self.load: list[list[float]] = []
        self.tracked: list[Tracked] = []
        self.nodes: dict[str, Any] = {}
        self.restart: dict[str, Any] = {}
        self.t_start = time.monotonic()
        self.publisher: SoakPublisher | None = None
        self.observer: SoakObserver | None = None
        # this process (publisher and observer) is sampled too, for reference
        self.tracked_self = Tracked("soak_driver", os.getpid(), 0.0)

    def now(self) -> float:
        """Seconds since the run started (since publishing began, once it has)."""
        return time.monotonic() - self.t_start

    def start(self, module: str, name: str) -> None:
        """Start a node process as `name`, tracked from now on."""
        params = self.seg_params if module == "segmenter_node" else self.cls_params
        node = NodeProcess(module, params, self.env, self.work / f"{name}.log")
        node.name = name
        self.nodes[name] = node
        self.tracked.append(Tracked(name, node.proc.pid, self.now()))

    def sample_all(self) -> None:
        """Sample RSS and CPU of every running process (this one too) and the load average."""
        t = self.now()
        for p in self.tracked:
            if not p.stopped:
                p.sample(t)
        self.tracked_self.sample(t)
        self.load.append([round(t, 1), *(round(x, 2) for x in os.getloadavg())])

    def progress(self) -> dict[str, Any]:
        """What has flowed so far: published, accepted, verdicts, RSS, load."""
        assert self.publisher is not None and self.observer is not None
        observer = self.observer
        st = self.publisher.stats
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
            "t_s": round(self.now(), 1),
            "published": {a: n + st.in_trial for a, n in st.published.items()},
            "trials": len(st.trials),
            **counts,
            "rss_mib": {p.name: p.samples[-1][1] for p in self.tracked if p.samples},
            "load_avg": self.load[-1][1:] if self.load else None,
        }

    def play(
        self,
        session: RosSession,
        source: Source,
        seconds: float,
        sample_s: float,
        restart_at: float,
        result: dict[str, Any],
    ) -> None:
        """Connect, publish `source` for `seconds` (sampling every `sample_s`, restarting the
        classifier at `restart_at` of the run), then wait for the nodes to drain."""
        qos = qos_profile(SegmenterConfig().qos_depth, "reliable")
        observer = self.observer = SoakObserver(session.node, qos)
        publisher = self.publisher = SoakPublisher(session.node, qos, source, seconds)
        result["startup_s"] = round(
            wait_for_nodes(
                lambda: publisher.matched() and observer.connected(session.node),
                STARTUP_TIMEOUT_S,
                list(self.nodes.values()),
                "the nodes to connect",
            ),
            2,
        )
        self.t_start = time.monotonic()
        for p in self.tracked:
            p.started_s = 0.0
        publisher.start()
        self._publish(session, restart_at * seconds, sample_s, result)
        publisher.stop_event.set()
        publisher.join(30.0)
        published_end = self.now()
        if result["aborted"] is None:
            self._drain(result)
        self.sample_all()
        result["publish_s"] = round(published_end, 1)

    def _publish(
        self, session: RosSession, restart_s: float, sample_s: float, result: dict[str, Any]
    ) -> None:
        """While the publisher runs: restart the classifier once at `restart_s`, sample every
        `sample_s` (progress.json and a line), stop at a node process that exited."""
        assert self.publisher is not None and self.observer is not None
        next_sample = 0.0
        while not self.publisher.stats.done:
            t = self.now()
            if not self.restart and t >= restart_s:
                self.restart.update(
                    _restart(
                        self.nodes, self.tracked, self.observer, session.node, self.now, self.start
                    )
                )
                if self.now() < next_sample:  # else the periodic sample right below
                    self.sample_all()
            if t >= next_sample:
                self.sample_all()
                next_sample += sample_s
                (self.work / "progress.json").write_text(json.dumps(self.progress(), indent=1))
                print(f"soak {json.dumps(self.progress())}", flush=True)
            if self._aborted_by_exit(t, result):
                break
            time.sleep(min(0.2, max(0.01, next_sample - self.now())))

    def _aborted_by_exit(self, t: float, result: dict[str, Any]) -> bool:
        """Whether a node process exited on its own: the run is aborted with its log tail."""
        dead = [
            (n, node)
            for n, node in self.nodes.items()
            if not node.alive() and not _by_name(self.tracked, n).stopped
        ]
        if not dead:
            return False
        name, node = dead[0]
        result["aborted"] = f"{name} exited (code {node.proc.returncode}) at {t:.0f} s"
        result["aborted_log_tail"] = node.tail(40)
        return True

    def _drain(self, result: dict[str, Any]) -> None:
        """Wait until the nodes took every sample and event published (else the run aborts)."""
        assert self.publisher is not None and self.observer is not None
        observer = self.observer
        st = self.publisher.stats

        def drained() -> bool:
            with observer.lock:
                return observer.applied["end"] >= st.end_events and all(
                    observer.streams_ended[a] >= st.end_events
                    and observer.accepted[a] + observer.rejected[a] >= st.published[a]
                    for a in ARMS
                )

        running = [n for name, n in self.nodes.items() if not _by_name(self.tracked, name).stopped]
        try:
            result["drain_s"] = round(
                wait_for_nodes(drained, DRAIN_TIMEOUT_S, running, "the drain"), 2
            )
        except InputError as exc:
            result["aborted"] = f"drain: {str(exc).splitlines()[0]}"
            result["aborted_log_tail"] = str(exc)

    def stop_nodes(self, result: dict[str, Any]) -> None:
        """Stop the publisher and the node processes still running, downstream first (the
        classifier, then the segmenter); keep the log tail of any that exited uncleanly."""
        if self.publisher is not None:
            self.publisher.stop_event.set()
        t_end = self.now()
        # downstream first: the classifier, then the segmenter
        for name in sorted(self.nodes, key=lambda n: n.startswith("segmenter")):
            p = _by_name(self.tracked, name)
            if not p.stopped:
                _stop(self.nodes[name], p, t_end)
                if p.exit_code != 0:
                    result.setdefault("shutdown_logs", {})[name] = self.nodes[name].tail(40)


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
        lambda: (
            observer.belief_sub.get_publisher_count() == 0
            and observer.diagnostics.segmenter_matched() < 2
        ),
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

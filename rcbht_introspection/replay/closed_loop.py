"""The closed loop over real DDS: sim_node, segmenter_node, classifier_node (when a sub-task
model is given), verifier_node and planner_node as processes of their own; a client starts each
trial's world (sim_node ~/start_trial), asks planner_node to run it (~/run_trial) and records
its decisions until the trial's stop. The same worlds as `rcbht closed-loop`, so the two can
be compared trial for trial."""

from __future__ import annotations

import re
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rcbht_introspection.configure.params import (
    ClassifierConfig,
    PlannerConfig,
    SegmenterConfig,
    SimNodeConfig,
    VerifierConfig,
)
from rcbht_introspection.errors import InputError
from rcbht_introspection.replay.supervision import (
    NodeProcess,
    lease_domain,
    release_domain,
    ros_env,
    wait_for_nodes,
    write_params,
)

TRIAL_TIMEOUT_S = 600.0
"""Longest wall time one trial may take (its attempts at rate_factor x real time)."""


@dataclass(frozen=True)
class RosLoopOptions:
    """How the nodes run: policy, files, speed, where the logs go."""

    work: Path
    policy: str
    verifier_file: str
    sim_config: str = ""
    recovery_file: str = ""
    model_file: str = ""
    rate_factor: float = 4.0
    record: bool = False
    """Keep what a timeline shows: /wrench, /task_state and the verdicts, as they arrived."""


@dataclass
class RosTrial:
    """One trial as the nodes ran it: its decisions (as rcbht/decision carried them)."""

    seed: int
    failure: str
    decisions: list[dict[str, Any]] = field(default_factory=list)
    timeline: Timeline | None = None


@dataclass
class Timeline:
    """What arrived during one trial, on the wall clock from its start (s)."""

    wrench: list[tuple[float, float, float, float]] = field(default_factory=list)
    """(t, Fx, Fy, Fz)."""
    states: list[tuple[float, str]] = field(default_factory=list)
    verdicts: list[tuple[float, bool, str]] = field(default_factory=list)
    """(t, alarm, failure class)."""
    decisions: list[tuple[float, dict[str, Any]]] = field(default_factory=list)


def _start(options: RosLoopOptions, env: dict[str, str]) -> list[NodeProcess]:
    w = options.work
    common = {"spin": "executor"}
    specs: list[tuple[str, type, dict[str, Any]]] = [
        ("segmenter_node", SegmenterConfig, {}),
        ("verifier_node", VerifierConfig, {"verifier_file": options.verifier_file}),
        ("sim_node", SimNodeConfig, {
            **common, "rate_factor": options.rate_factor, "sim_config": options.sim_config,
            "recovery_file": options.recovery_file}),
        ("planner_node", PlannerConfig, {
            **common, "policy": options.policy, "verifier_file": options.verifier_file,
            "recovery_file": options.recovery_file}),
    ]  # fmt: skip
    if options.model_file:
        specs.insert(1, ("classifier_node", ClassifierConfig, {"model_file": options.model_file}))
    return [
        NodeProcess(name, write_params(w / f"{name}.yaml", cls, values), env, w / f"{name}.log")
        for name, cls, values in specs
    ]


SAMPLE_COUNTS = {
    "sim_node": re.compile(r"samples published (\d+)"),
    "segmenter_node": re.compile(r"samples \(accepted, rejected\) per arm \{'R': \((\d+), (\d+)\)"),
    "verifier_node": re.compile(r"samples \(accepted, rejected\) per arm \{'R': \((\d+), (\d+)\)"),
}
"""Each node's last log line of samples: published by sim_node, accepted (and rejected)."""


def sample_counts(work: Path) -> dict[str, list[int]]:
    """Samples per node from their logs: sim_node's published, the others' accepted and
    rejected (dropped = published - accepted)."""
    out: dict[str, list[int]] = {}
    for name, pattern in SAMPLE_COUNTS.items():
        log = work / f"{name}.log"
        found = pattern.findall(log.read_text()) if log.is_file() else []
        if found:
            last = found[-1]
            out[name] = [int(v) for v in ((last,) if isinstance(last, str) else last)]
    return out


def run_over_ros(
    trials: Sequence[tuple[int, str | None]], options: RosLoopOptions
) -> tuple[list[RosTrial], dict[str, int | None]]:
    """Run the trials through the node processes; their decisions and each node's exit code
    after SIGINT (0: a clean stop)."""
    from rcbht_introspection.rostools.session import RosSession

    options.work.mkdir(parents=True, exist_ok=True)
    domain = lease_domain()
    procs = _start(options, ros_env(domain, options.work / "ros_log"))
    codes: dict[str, int | None] = {}
    try:
        with RosSession("rcbht_closed_loop", domain_id=domain) as ros:
            client = _LoopClient(ros.node, options.record)
            wait_for_nodes(client.ready, 120.0, procs, "sim_node and planner_node services")
            runs = [client.run(seed, failure, options, procs) for seed, failure in trials]
    finally:
        for p in procs:
            codes[p.name] = p.stop()
        release_domain(domain)
    return runs, codes


class _LoopClient:
    """The client side: the two services and the decision topic."""

    def __init__(self, node: Any, record: bool) -> None:
        from geometry_msgs.msg import WrenchStamped
        from rcbht_interfaces.msg import PlanDecision, Verdict
        from rcbht_interfaces.srv import RunTrial, StartTrial
        from std_msgs.msg import String

        self.start = node.create_client(StartTrial, "/sim_node/start_trial")
        self.run_trial = node.create_client(RunTrial, "/planner_node/run_trial")
        self.decisions: list[Any] = []
        node.create_subscription(PlanDecision, "rcbht/decision", self._on_decision, 10000)
        self.count = 0
        self.timeline: Timeline | None = None
        self.t0 = time.monotonic()
        if record:
            node.create_subscription(WrenchStamped, "/wrench", self._on_wrench, 10000)
            node.create_subscription(String, "/task_state", self._on_state, 1000)
            node.create_subscription(Verdict, "rcbht/verdict", self._on_verdict, 10000)

    def _now(self) -> float:
        return time.monotonic() - self.t0

    def _on_decision(self, msg: Any) -> None:
        self.decisions.append(msg)
        if self.timeline is not None:
            self.timeline.decisions.append((self._now(), _decision(msg)))

    def _on_wrench(self, msg: Any) -> None:
        if self.timeline is not None:
            f = msg.wrench.force
            self.timeline.wrench.append((self._now(), f.x, f.y, f.z))

    def _on_state(self, msg: Any) -> None:
        if self.timeline is not None:
            self.timeline.states.append((self._now(), msg.data))

    def _on_verdict(self, msg: Any) -> None:
        if self.timeline is not None:
            self.timeline.verdicts.append((self._now(), bool(msg.alarm), msg.failure_class))

    def ready(self) -> bool:
        return bool(self.start.service_is_ready() and self.run_trial.service_is_ready())

    def _call(self, client: Any, request: Any, procs: Sequence[NodeProcess]) -> Any:
        future = client.call_async(request)
        wait_for_nodes(future.done, 120.0, procs, f"{client.srv_name}")
        return future.result()

    def run(
        self, seed: int, failure: str | None, options: RosLoopOptions, procs: Sequence[NodeProcess]
    ) -> RosTrial:
        from rcbht_interfaces.srv import RunTrial, StartTrial

        started = self._call(
            self.start, StartTrial.Request(seed=seed, failure=failure or ""), procs
        )
        if not started.accepted:
            raise InputError(f"sim_node refused trial {seed}: {started.message}")
        self.count += 1
        if options.record:
            self.timeline, self.t0 = Timeline(), time.monotonic()
        truth = list(started.truth) if options.policy == "oracle" else []
        asked = self._call(self.run_trial, RunTrial.Request(trial=self.count, truth=truth), procs)
        if not asked.accepted:
            raise InputError(f"planner_node refused trial {seed}: {asked.message}")
        trial = RosTrial(seed, failure or "")

        def stopped() -> bool:
            return any(d.trial == self.count and d.kind == "stop" for d in self.decisions)

        wait_for_nodes(stopped, TRIAL_TIMEOUT_S, procs, f"the end of trial {seed}")
        time.sleep(0.05)
        trial.decisions = [_decision(d) for d in self.decisions if d.trial == self.count]
        trial.timeline, self.timeline = self.timeline, None
        return trial


def _decision(msg: Any) -> dict[str, Any]:
    return {
        "kind": msg.kind,
        "attempt": int(msg.attempt),
        "time": round(float(msg.time), 6),
        "correction": {
            "x": round(msg.dx, 7), "y": round(msg.dy, 7), "z": round(msg.dz, 7),
            "yaw": round(msg.dyaw, 7),
        },
        "failure_class": msg.failure_class,
        "reason": msg.reason,
    }  # fmt: skip

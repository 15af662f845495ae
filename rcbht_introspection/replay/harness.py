"""`rcbht replay-eval`: replay trial bags through segmenter_node and classifier_node and score them.

The two nodes run as separate processes over real DDS, isolated as supervision.py isolates them
(a leased ROS_DOMAIN_ID, loopback only, logs in a temporary ROS_LOG_DIR). This process plays
each bag with its recorded timing divided by `rate` and records /task_state, the beliefs, the
applied sub-task events and the words (observer.py); scoring.py compares them with the truth
in the bag and with the offline run of the same stream and model.

Teaching (`teach_first` K): the classifier starts without a model (a cold start), the first K
bags are played in order and after each one its sub-tasks are taught through the classifier's
~/teach service with their true names and [start, end] (the windows of its verdicts, which the
applied sub-task events bound), waiting until the node reports nothing pending; the other bags
are then scored with the taught model (saved by the node, the offline reference). With
`teach_restart` the classifier is restarted from the saved model and the scored bags are
played again: the verdicts must be the same. With `teach_beside` a taught bag's sub-tasks are
learned while the next taught bag plays (the last one's before the scored bags), so the node
learns beside its live path; those bags' sample -> belief latency is reported apart
(`teach.latency_beside_ms`).
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rclpy.node import Node

from rcbht_introspection.configure.params import (
    ClassifierConfig,
    SegmenterConfig,
    VerifierConfig,
    load_node_config,
    segmenter_taxonomy,
)
from rcbht_introspection.configure.spin import DEFAULT_SPIN, Spin
from rcbht_introspection.errors import InputError
from rcbht_introspection.io.bags import (
    PHASE_TOPIC,
    WRENCH_TYPE,
    BagMessage,
    bag_messages,
    decode_wrench,
    read_trial_bag,
    wrench_topic,
)
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.learn.model_file import load_model
from rcbht_introspection.live import BeliefMode
from rcbht_introspection.live.offline import percentiles_ms
from rcbht_introspection.live.segmenter import arm_stream_factory
from rcbht_introspection.live.state import TaskStateConfig
from rcbht_introspection.nodes.common import qos_profile
from rcbht_introspection.replay.observer import DiagnosticWatch, Observer, VerdictObserver
from rcbht_introspection.replay.scoring import (
    BagRecord,
    Latencies,
    Mark,
    Playback,
    Reference,
    bag_record,
    score,
)
from rcbht_introspection.replay.supervision import (
    NodeProcess,
    environment,
    lease_domain,
    release_domain,
    ros_env,
    sigterm_as_interrupt,
    wait_for_nodes,
    write_params,
)
from rcbht_introspection.replay.verify_scoring import (
    VerdictRecord,
    verdict_latencies,
    verifier_scores,
)
from rcbht_introspection.rostools.player import BagPlayer
from rcbht_introspection.rostools.session import RosSession
from rcbht_introspection.rostools.teach_client import call_teach, teach_client, teach_request
from rcbht_introspection.taxonomy import StreamProfile
from rcbht_introspection.taxonomy.config import TaxonomyConfig
from rcbht_introspection.verify.model_file import VerifierModel, load_verifier
from rcbht_introspection.waiting import wait_until

TEACH_ANSWER_S = 60.0
"""How long the harness waits for ~/teach to answer (re-sent every 2 s): the classifier serves it
between words, beside its learner process, on a machine the replay may keep busy."""


@dataclass(frozen=True)
class ReplayEvalOptions:
    """How to run a replay evaluation."""

    rate: float = 1.0
    mode: BeliefMode = "boundary"
    profile: str = ""
    """Taxonomy profile of config/rcbht.yaml or of taxonomy_config_file (neither: the model's)."""
    taxonomy_config_file: str = ""
    """A file of taxonomy profiles, e.g. from `rcbht calibrate` (empty: config/rcbht.yaml)."""
    stream_profile: StreamProfile = "reference"
    spin: Spin = DEFAULT_SPIN
    """The nodes' `spin` parameter: rclpy's EventsExecutor or its SingleThreadedExecutor."""
    state: TaskStateConfig | None = None
    """classifier_node's `state.*` parameters (None: those of config/classifier.yaml)."""
    startup_timeout: float = 60.0
    drain_timeout: float = 60.0
    domain_id: int | None = None
    log_dir: Path | None = None
    """Keep the node logs here (default: a temporary folder, removed afterwards)."""
    offline: bool = True
    """Also compute the offline references (words and verdicts)."""
    teach_first: int = 0
    """> 0: start without a model and teach the first this many bags (module doc)."""
    teach_restart: bool = False
    """After teaching: restart the classifier from the saved model, replay the scored bags."""
    teach_file: Path | None = None
    """Where the classifier saves the taught model (default: in the work folder)."""
    teach_beside: bool = False
    """Learn each taught bag while the next taught bag plays (module doc)."""
    teach_timeout: float = 600.0
    """Longest wait for one bag's sub-tasks to be learned."""
    verifier_file: Path | None = None
    """A verifier file (`rcbht verify-train`): verifier_node runs too and its alarms are scored."""


def _params(
    work: Path, arms: tuple[str, ...], model_path: Path | None, options: ReplayEvalOptions
) -> tuple[SegmenterConfig, ClassifierConfig, Path, Path]:
    """The nodes' configurations, and their parameter files written to `work`."""
    seg = _segmenter(model_path, options, arms)
    seg_params = write_params(
        work / "segmenter.yaml",
        SegmenterConfig,
        {
            "arms": list(arms),
            "wrench_topics": list(seg.wrench_topics),
            "taxonomy_profile": seg.taxonomy_profile,
            "taxonomy_config_file": seg.taxonomy_config_file,
            "taxonomy_model_file": seg.taxonomy_model_file,
            "stream_profile": seg.stream_profile,
            "spin": seg.spin,
        },
    )
    values: dict[str, Any] = {
        "spin": options.spin,
        "model_file": seg.taxonomy_model_file,  # the model the segmenter takes its profile from
        "mode": options.mode,
        "arms": list(arms),
        **({"state": dataclasses.asdict(options.state)} if options.state is not None else {}),
    }
    if options.teach_first:
        values.update(
            model_file=str(teach_path(work, options).resolve()),
            teach_enabled=True,
            teach_history_s=TEACH_HISTORY_S,
        )
    cls_params = write_params(work / "classifier.yaml", ClassifierConfig, values)
    # what the node reads from the file (the offline reference runs with its state rule)
    cls_cfg = load_node_config(ClassifierConfig, cls_params)
    return seg, cls_cfg, seg_params, cls_params


def _segmenter(
    model_path: Path | None, options: ReplayEvalOptions, arms: tuple[str, ...] = ("R",)
) -> SegmenterConfig:
    """segmenter_node's configuration in a replay of `arms`: the options' profiles, and the model
    file, whose embedded profile labels the words when the options name none."""
    return SegmenterConfig(
        arms=arms,
        wrench_topics=tuple(wrench_topic(a, arms) for a in arms),
        taxonomy_profile=options.profile,
        taxonomy_config_file=options.taxonomy_config_file,
        taxonomy_model_file=str(Path(model_path).resolve()) if model_path else "",
        stream_profile=options.stream_profile,
        spin=options.spin,
    )


def verifier_params(
    work: Path, arms: tuple[str, ...], verifier: Path, spin: Spin = DEFAULT_SPIN
) -> tuple[VerifierConfig, Path]:
    """verifier_node's configuration for `arms` and its parameter file in `work`."""
    cfg = VerifierConfig(
        verifier_file=str(Path(verifier).resolve()),
        arms=arms,
        wrench_topics=tuple(wrench_topic(a, arms) for a in arms),
    )
    values = {
        "verifier_file": cfg.verifier_file,
        "arms": list(arms),
        "wrench_topics": list(cfg.wrench_topics),
        "spin": spin,
    }
    return cfg, write_params(work / "verifier.yaml", VerifierConfig, values)


def check_verifier(path: Path, arms: tuple[str, ...]) -> VerifierModel:
    """The verifier file of a replay, usable for the bags' arms (else a one-line InputError)."""
    if not Path(path).is_file():
        raise InputError("no such verifier file", path)
    model = load_verifier(path)
    if set(model.arms) != set(arms):
        raise InputError(
            f"the verifier's arms {list(model.arms)} are not the bags' {list(arms)}", path
        )
    return model


TEACH_HISTORY_S = 600.0
"""classifier_node's teach_history_s in a teaching replay: a whole trial's words stay."""


def teach_path(work: Path, options: ReplayEvalOptions) -> Path:
    """Where the classifier of a teaching replay saves its taught model."""
    return Path(options.teach_file) if options.teach_file else work / "taught.rcbht"


def _check_request(
    bags: list[Path], model_path: Path | None, options: ReplayEvalOptions
) -> TaxonomyConfig:
    """The profile the segmenter will label with; one-line errors for a replay that cannot run:
    no model file, a bad rate, teaching options that do not fit, a model of another profile."""
    if model_path is not None and not Path(model_path).is_file():
        raise InputError("no such model file", model_path)
    if options.rate <= 0:
        raise InputError(f"rate must be > 0, got {options.rate}", field="rate")
    if options.teach_first:
        _check_teaching(len(bags), model_path, options)
    if model_path is not None:
        load_model(model_path)  # a file the classifier node could not load is refused here
    return segmenter_taxonomy(_segmenter(model_path, options))


def _check_teaching(n_bags: int, model_path: Path | None, options: ReplayEvalOptions) -> None:
    """A teaching replay starts cold, teaches some bags and scores the rest in boundary mode."""
    if model_path is not None:
        raise InputError("teaching starts without a model: give no --model")
    if not 0 < options.teach_first < n_bags:
        raise InputError(
            f"teach_first must be in [1, {n_bags - 1}] (bags left to score), "
            f"got {options.teach_first}",
            field="teach_first",
        )
    if options.mode != "boundary":
        raise InputError("teaching needs boundary mode (sub-task verdicts)", field="mode")
    if options.teach_file is not None and Path(options.teach_file).exists():
        raise InputError(
            "the taught model's file exists already (a cold start needs none)",
            options.teach_file,
        )


def _read_bags(bags: list[Path]) -> tuple[list[Trial], tuple[str, ...]]:
    """The bags' trials and their arms (every bag must have the first one's)."""
    trials = [read_trial_bag(b) for b in bags]
    arms = trials[0].arms
    for b, t in zip(bags, trials, strict=True):
        if t.arms != arms:
            raise InputError(f"arms {list(t.arms)} differ from the first bag's {list(arms)}", b)
    return trials, arms


@dataclass(frozen=True)
class _Workspace:
    """Where and how a replay's nodes run: work folder, environment, domain, configurations."""

    work: Path
    env: dict[str, str]
    domain_id: int
    seg: SegmenterConfig
    classifier: ClassifierConfig
    seg_params: Path
    cls_params: Path
    started: float
    """time.monotonic() when the nodes were about to start"""


def _start_nodes(
    procs: list[NodeProcess], ws: _Workspace, arms: tuple[str, ...], options: ReplayEvalOptions
) -> VerifierConfig | None:
    """Start the node processes into `procs` (one at a time: a failed start still stops the
    earlier ones); the verifier's configuration when it runs."""
    work, env = ws.work, ws.env
    procs.append(NodeProcess("segmenter_node", ws.seg_params, env, work / "segmenter_node.log"))
    procs.append(NodeProcess("classifier_node", ws.cls_params, env, work / "classifier_node.log"))
    if options.verifier_file is None:
        return None
    ver_cfg, ver_params = verifier_params(work, arms, options.verifier_file, options.spin)
    procs.append(NodeProcess("verifier_node", ver_params, env, work / "verifier_node.log"))
    return ver_cfg


class _Graph:
    """This process's side of the ROS graph: the observers, the bag player, and the checks
    that the nodes are connected (or the classifier gone)."""

    def __init__(
        self,
        node: Node,
        ws: _Workspace,
        ver_cfg: VerifierConfig | None,
        bags: list[Path],
        arms: tuple[str, ...],
        procs: list[NodeProcess],
        options: ReplayEvalOptions,
    ) -> None:
        qos = qos_profile(ws.seg.qos_depth, "reliable")
        self.node = node
        self.arms = arms
        self.procs = procs
        self.options = options
        self.observer = Observer(node, ws.seg, ws.classifier, qos)
        self.verdicts = VerdictObserver(node, ver_cfg, qos) if ver_cfg else None
        self.player = BagPlayer(node, qos)
        self.messages = [list(bag_messages(b)) for b in bags]
        for msgs in self.messages:
            self.player.prepare(msgs)
        self.needed = [wrench_topic(a, arms) for a in arms] + [PHASE_TOPIC]
        self.classifier_inputs = ["/" + t for t in self.observer.word_topics.values()] + [
            "/" + ws.seg.applied_phase_topic
        ]
        self.diagnostics = DiagnosticWatch(node)

    def ready(self) -> bool:
        """Every reader and writer of the replay has matched its peers."""
        # the graph shows a reader before the writer's side has matched it (and a writer before
        # the reader's side has); messages sent in between are lost, so the nodes' own
        # /diagnostics must count the segmenter's readers (observer, classifier), the verifier's
        # reader (observer) and the publishers the nodes' readers matched
        verdicts, diagnostics = self.verdicts, self.diagnostics
        readers = 2 if verdicts is not None else 1  # segmenter (+ verifier)
        publishers = self.player.publishers
        return (
            all(publishers[t].get_subscription_count() >= readers for t in self.needed)
            and all(s.get_publisher_count() > 0 for s in self.observer.subs)
            and (verdicts is None or all(s.get_publisher_count() > 0 for s in verdicts.subs))
            and all(self.node.count_subscribers(t) >= 2 for t in self.classifier_inputs)
            and diagnostics.segmenter_matched() >= 2
            and diagnostics.classifier_matched()
            and diagnostics.intake_matched()
            and (verdicts is None or diagnostics.verifier_matched())
        )

    def classifier_gone(self) -> bool:
        """The graph and the segmenter's diagnostics no longer see the classifier."""
        return self.diagnostics.segmenter_matched() < 2 and all(
            self.node.count_subscribers(t) < 2 for t in self.classifier_inputs
        )

    def play(
        self, bag: Path, msgs: list[BagMessage], stream_id: int
    ) -> tuple[BagRecord, VerdictRecord | None]:
        """Play one bag, wait until every verdict and end-of-stream arrived; return its records
        (the classifier's, and the verifier's when it runs)."""
        observer, options = self.observer, self.options
        observer.convert()
        with observer.lock:
            since = observer.obs.mark()
        playback = Playback(bag)
        t0 = time.monotonic()
        self.player.play(msgs, rate=options.rate, on_publish=playback.on_publish)
        playback.play_s = time.monotonic() - t0
        drain = _BagDrain(self, stream_id, since, playback, msgs)
        wait_for_nodes(
            drain.done,
            options.drain_timeout,
            self.procs,
            f"the verdicts of {bag.name}",
            drain.progress,
        )
        observer.convert()
        verdict_record = self.verdicts.record(stream_id) if self.verdicts is not None else None
        if verdict_record is not None:
            verdict_record.latencies_ns = verdict_latencies(
                playback.pub_series, verdict_record.arrivals
            )
        with observer.lock:
            return bag_record(observer.obs, since, stream_id, self.arms, playback), verdict_record


class _BagDrain:
    """What a played bag still waits for: its verdicts, its end of stream on every arm, the
    last state change, and the verifier reaching the bag's end."""

    def __init__(
        self, graph: _Graph, stream_id: int, since: Mark, playback: Playback, msgs: list[BagMessage]
    ) -> None:
        self.graph = graph
        self.stream_id = stream_id
        self.since = since
        self.playback = playback
        n_subtasks = sum(1 for m in msgs if m.topic == PHASE_TOPIC) - 1  # minus the end event
        self.n_subtasks = 0 if graph.options.mode == "window" else n_subtasks  # window: none
        stamps = [decode_wrench(m.raw)[0] for m in msgs if m.msgtype == WRENCH_TYPE]
        self.end_time = (max(stamps) - min(stamps)) / 1e9 if stamps else 0.0

    def done(self) -> bool:
        """Everything of the bag has arrived."""
        observer, verdicts = self.graph.observer, self.graph.verdicts
        if not observer.ended(self.stream_id, self.graph.arms):
            return False
        finals = observer.finals_since(self.since.beliefs)
        return (
            len(finals) >= self.n_subtasks
            # a state change published with the last verdict belongs to this bag
            and (not finals or observer.state_settled(finals[-1].sent_ns))
            and (verdicts is None or verdicts.reached(self.stream_id, self.end_time))
        )

    def progress(self) -> str:
        """What has arrived so far (for a time-out's message)."""
        observer, since = self.graph.observer, self.since
        obs = observer.obs
        return (
            f"{len(observer.finals_since(since.beliefs))}/{self.n_subtasks} verdicts, end of stream "
            f"{sorted(k[1:] for k in obs.ends if k[0] == self.stream_id)}, "
            f"{self.playback.published} wrench published; received "
            f"{len(obs.word_arrivals) - since.word_arrivals} word messages, "
            f"{len(obs.beliefs) - since.beliefs} beliefs, "
            f"{len(obs.states) - since.states} state changes, {len(obs.phases)} events"
        )


Plays = list[tuple[Path, list[BagMessage]]]
"""Each bag with its messages, in play order."""


def _teach(
    graph: _Graph, plays: Plays, trials: list[Trial], options: ReplayEvalOptions
) -> tuple[dict[str, Any], dict[str, int]]:
    """Play and teach the first teach_first bags (module doc); the teaching report and the
    samples the segmenter accepted so far per arm."""
    k = options.teach_first
    client = teach_client(graph.node)
    taught = []
    beside = Latencies()  # bags played while the previous one was learned
    learning: tuple[BagRecord, Trial, _Sent] | None = None
    accepted_before: dict[str, int] = {}
    for stream_id, (bag, msgs) in enumerate(plays[:k]):
        rec, _ = graph.play(bag, msgs, stream_id)
        if learning is not None:
            beside.add(rec)
            taught.append(_wait_taught(client, *learning, options))
        sent = _send_teach(client, rec, trials[stream_id])
        learning = (rec, trials[stream_id], sent)
        if not options.teach_beside or stream_id == k - 1:
            taught.append(_wait_taught(client, *learning, options))
            learning = None
        accepted_before = {a: rec.ends.get((a, "primitives"), (0, 0))[0] for a in graph.arms}
    report = _teach_summary(taught)
    if options.teach_beside:
        report["latency_beside_ms"] = percentiles_ms(beside.belief)
    return report, accepted_before


def _restart_classifier(
    graph: _Graph,
    ws: _Workspace,
    codes: dict[str, int | None],
    plays: Plays,
    records: list[BagRecord],
) -> dict[str, Any]:
    """Restart the classifier from its saved model and replay the scored bags: the verdicts
    before and after."""
    procs, options, k = graph.procs, graph.options, graph.options.teach_first
    procs[1].interrupt()
    codes["classifier_node (taught)"] = procs[1].stop()
    # the graph and the segmenter's diagnostics must first see it gone
    wait_for_nodes(
        graph.classifier_gone,
        options.startup_timeout,
        procs[:1],
        "the classifier to leave the graph",
    )
    graph.diagnostics.forget("classifier_node: belief")  # its successor reports its own matches
    procs[1] = NodeProcess(
        "classifier_node", ws.cls_params, ws.env, ws.work / "classifier_node_restarted.log"
    )
    wait_for_nodes(graph.ready, options.startup_timeout, procs, "the restarted classifier")
    again = [
        graph.play(bag, msgs, stream_id)[0]
        for stream_id, (bag, msgs) in enumerate(plays[k:], start=len(plays))
    ]
    return _restart_summary(records, again)


def _live_session(
    bags: list[Path],
    trials: list[Trial],
    ws: _Workspace,
    options: ReplayEvalOptions,
    procs: list[NodeProcess],
    codes: dict[str, int | None],
    result: dict[str, Any],
) -> tuple[list[BagRecord], list[VerdictRecord], dict[str, int]]:
    """Start the nodes, connect, teach (when asked), play the scored bags (and again after a
    restart); the records, the verifier's records and the samples accepted before."""
    arms = trials[0].arms
    ver_cfg = _start_nodes(procs, ws, arms, options)
    with RosSession("rcbht_replay_eval", domain_id=ws.domain_id) as ros:
        graph = _Graph(ros.node, ws, ver_cfg, bags, arms, procs, options)
        wait_for_nodes(graph.ready, options.startup_timeout, procs, "the nodes to connect")
        result["startup_s"] = round(time.monotonic() - ws.started, 2)
        plays = list(zip(bags, graph.messages, strict=True))
        accepted_before: dict[str, int] = {}
        k = options.teach_first
        if k:
            result["teach"], accepted_before = _teach(graph, plays, trials, options)
        played = [
            graph.play(bag, msgs, stream_id)
            for stream_id, (bag, msgs) in enumerate(plays[k:], start=k)
        ]
        records = [rec for rec, _ in played]
        verdict_records = [v for _, v in played if v is not None]
        if k and options.teach_restart:
            result["restart"] = _restart_classifier(graph, ws, codes, plays, records)
    return records, verdict_records, accepted_before


def _stop_nodes(
    procs: list[NodeProcess],
    codes: dict[str, int | None],
    result: dict[str, Any],
    options: ReplayEvalOptions,
    domain_id: int,
) -> None:
    """Stop every node (keeping a failed one's log tail), kill any left, release the domain."""
    for p in procs:  # both stop at once: a Ctrl-C of the harness ends within seconds
        p.interrupt()
    try:
        for p in procs:
            codes[p.name] = p.stop()
            if codes[p.name] != 0:  # the node log is in a temporary folder: keep its end
                result.setdefault("shutdown_logs", {})[p.name] = p.tail(40)
    finally:
        for p in procs:  # a second Ctrl-C while waiting: no node is left behind
            if p.alive():
                p.proc.kill()
        if not options.domain_id:
            release_domain(domain_id)  # its nodes are gone


def _verifier_report(
    records: list[VerdictRecord],
    trials: list[Trial],
    verifier: VerifierModel,
    options: ReplayEvalOptions,
) -> dict[str, Any]:
    """The verifier's part of the report: its file, scores and sample -> verdict latency."""
    return {
        "file": str(options.verifier_file),
        **verifier_scores(records, trials, verifier, options.offline),
        "sample_to_verdict_ms": percentiles_ms([n for r in records for n in r.latencies_ns]),
    }


def replay_eval(
    bags: list[Path], model_path: Path | None, options: ReplayEvalOptions
) -> dict[str, Any]:
    """Run the live pipeline on `bags` and return the scores (see module doc).

    Without a model (None) the classifier publishes "unknown"; latencies and drops still count.
    """
    taxonomy = _check_request(bags, model_path, options)
    trials, arms = _read_bags(bags)
    verifier = check_verifier(options.verifier_file, arms) if options.verifier_file else None
    domain_id = options.domain_id or lease_domain()
    tmp = tempfile.TemporaryDirectory(prefix="rcbht-replay-")
    work = Path(options.log_dir) if options.log_dir else Path(tmp.name)
    work.mkdir(parents=True, exist_ok=True)
    env = ros_env(domain_id, work / "ros_log")
    seg, cls_cfg, seg_params, cls_params = _params(work, arms, model_path, options)
    ws = _Workspace(work, env, domain_id, seg, cls_cfg, seg_params, cls_params, time.monotonic())
    result: dict[str, Any] = {}
    codes: dict[str, int | None] = {}
    with environment(env), sigterm_as_interrupt():
        procs: list[NodeProcess] = []
        try:
            records, verdict_records, accepted_before = _live_session(
                bags, trials, ws, options, procs, codes, result
            )
        finally:
            _stop_nodes(procs, codes, result, options, domain_id)
    scored_trials = trials[options.teach_first :]
    if options.teach_first:
        model_path = teach_path(work, options)
    result.update(
        _score(records, scored_trials, model_path, options, cls_cfg, arms, accepted_before)
    )
    if verifier is not None:
        result["verifier"] = _verifier_report(verdict_records, scored_trials, verifier, options)
    result.update(
        {
            "bags": [str(b) for b in bags],
            "rate": options.rate,
            "mode": options.mode,
            "profile": taxonomy.profile,
            "stream_profile": options.stream_profile,
            "model": str(model_path),
            "teach_first": options.teach_first,
            "domain_id": domain_id,
            "exit_codes": codes,
            "clean_shutdown": all(c == 0 for c in codes.values()),
            "wall_s": round(time.monotonic() - ws.started, 2),
        }
    )
    tmp.cleanup()
    return result


@dataclass(frozen=True)
class _Sent:
    """Teach requests sent for one bag: its sub-tasks, when, and how long each call took (s)."""

    subtasks: list[str]
    at: float
    call_s: list[float]


def _send_teach(client: Any, rec: BagRecord, trial: Trial) -> _Sent:
    """Teach the sub-tasks of a played bag (true names, its verdicts' windows)."""
    truth = [s for s, _, _ in trial.subtask_bounds()]
    finals = [r.belief for r in rec.beliefs if r.belief.final]
    if len(finals) != len(truth):
        raise InputError(f"{len(finals)} verdicts for {len(truth)} sub-tasks", rec.playback.bag)
    t0 = time.monotonic()
    calls = []
    for label, belief in zip(truth, finals, strict=True):
        sent = time.monotonic()
        response = call_teach(
            client, teach_request(label, belief.start, belief.end), TEACH_ANSWER_S
        )
        calls.append(round(time.monotonic() - sent, 4))
        if not response.accepted:
            raise InputError(f"teaching {label!r} refused: {response.message}", rec.playback.bag)
    return _Sent(truth, t0, calls)


def _wait_taught(
    client: Any, rec: BagRecord, trial: Trial, sent: _Sent, options: ReplayEvalOptions
) -> dict[str, Any]:
    """Wait until the classifier has learned everything sent; the bag's latencies."""
    status = None

    def learned() -> bool:
        nonlocal status
        status = call_teach(client, teach_request(""), TEACH_ANSWER_S)
        return bool(status.pending == 0)

    if not wait_until(learned, options.teach_timeout, poll=0.05):
        raise InputError(f"not learned within {options.teach_timeout} s", rec.playback.bag)
    assert status is not None
    return {
        "name": trial.name,
        "subtasks": sent.subtasks,
        "call_s": sent.call_s,
        "learned_s": round(time.monotonic() - sent.at, 3),
        "taught_windows": status.taught_windows,
        "model_version": status.model_version,
        "errors": status.errors,
    }


def _teach_summary(taught: list[dict[str, Any]]) -> dict[str, Any]:
    """The teaching part of the report."""
    learned = [t["learned_s"] for t in taught]
    return {
        "taught_trials": [t["name"] for t in taught],
        "taught_windows": taught[-1]["taught_windows"],
        "model_version": taught[-1]["model_version"],
        "errors": taught[-1]["errors"],
        "trial_latency_s": learned,
        "trial_latency_max_s": max(learned),
        "per_trial": taught,
    }


def _restart_summary(first: list[BagRecord], again: list[BagRecord]) -> dict[str, Any]:
    """Verdicts of the scored bags before and after the classifier restarted from its file."""

    def verdicts(records: list[BagRecord]) -> list[list[str]]:
        return [[r.belief.subtask for r in rec.beliefs if r.belief.final] for rec in records]

    return {
        "verdicts_equal": verdicts(first) == verdicts(again),
        "verdicts_after_restart": verdicts(again),
    }


def load_reference(
    model_path: Path, options: ReplayEvalOptions, classifier: ClassifierConfig
) -> Reference:
    """The model file, the stream factory and the classifier settings that the nodes use (the
    offline run to compare)."""
    taxonomy = segmenter_taxonomy(_segmenter(model_path, options))
    factory = arm_stream_factory(stream_profile=options.stream_profile, taxonomy=taxonomy)
    return Reference(load_model(model_path), factory, classifier.state, classifier.window_s)


def _score(
    records: list[BagRecord],
    trials: list[Trial],
    model_path: Path | None,
    options: ReplayEvalOptions,
    classifier: ClassifierConfig,
    arms: tuple[str, ...],
    accepted_before: dict[str, int] | None = None,
) -> dict[str, Any]:
    """The scores, with the offline reference when asked for and a model was given."""
    reference = None
    if options.offline and model_path is not None:
        reference = load_reference(model_path, options, classifier)
    return score(records, trials, arms, options.mode, reference, accepted_before)

"""Typed, validated parameters of the segmenter and classifier nodes (no rclpy import).

Each node declares one ROS parameter per field (read-only, with the field's description) and
turns the values back into its config object here, so a bad value is a one-line error naming the
parameter. config/segmenter.yaml and config/classifier.yaml are ROS parameter files
(`--ros-args --params-file ...`) holding the defaults; `load_node_config` reads them without ROS.
"""

from __future__ import annotations

import dataclasses
import re
import typing
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, TypeVar

from rcbht_introspection.config_files import (
    config_from_document,
    config_path,
    from_mapping,
    read_yaml,
)
from rcbht_introspection.config_files import described as _f
from rcbht_introspection.configure.spin import DEFAULT_SPIN, SPIN_HELP, Spin
from rcbht_introspection.errors import InputError
from rcbht_introspection.live import BeliefMode
from rcbht_introspection.live.intake import IntakeConfig, check_intake
from rcbht_introspection.live.state import TaskStateConfig, check_task_state
from rcbht_introspection.task import Task, load_task_file
from rcbht_introspection.taxonomy import StreamProfile
from rcbht_introspection.taxonomy.config import TaxonomyConfig, load_taxonomy_config

Reliability = Literal["reliable", "best_effort"]
"""QoS reliability of every subscription and publisher of a node."""
LEVEL_TOPICS: tuple[str, ...] = ("primitives", "compositions", "behaviors")


QOS_DEPTH_HELP = "history depth of every subscription and publisher (10 s of a 1 kHz sensor)"


@dataclass(frozen=True)
class SegmenterConfig:
    """segmenter_node: wrench topics per arm -> RCBHT words per level (and arm)."""

    arms: tuple[str, ...] = _f(("R",), "arm names, one or two (e.g. [R] or [L, R])")
    wrench_topics: tuple[str, ...] = _f(
        ("/wrench",), "geometry_msgs/WrenchStamped topic of each arm, in `arms` order"
    )
    phase_topic: str = _f(
        "/task_phase", "std_msgs/String sub-task events of the task's state machine"
    )
    words_namespace: str = _f(
        "rcbht", "words go to <ns>/{primitives,compositions,behaviors}; two arms: <arm>/<ns>/..."
    )
    applied_phase_topic: str = _f(
        "rcbht/phase", "rcbht_interfaces/Phase: each /task_phase event placed on the stream clock"
    )
    end_phases: tuple[str, ...] = _f(("done",), "event names that end the task (flush the streams)")
    task_file: str = _f(
        "",
        "task.yaml naming the sub-tasks; other event names are counted as unknown and ignored "
        "(empty: every event that is not an end phase starts a sub-task)",
    )
    event_hold_s: float = _f(
        0.2,
        "an event no later sample applies (the end event) is applied after this long once the "
        "samples published before it have all arrived",
    )
    event_max_hold_s: float = _f(
        10.0, "... and after this long in any case (samples lost or the sensor stopped earlier)"
    )
    taxonomy_profile: str = _f(
        "",
        "taxonomy profile of config/rcbht.yaml (empty: the one taxonomy_model_file carries, else "
        "reference), or of taxonomy_config_file (empty: its only profile)",
    )
    taxonomy_config_file: str = _f(
        "",
        "optional YAML file of taxonomy profiles instead of config/rcbht.yaml (e.g. from `rcbht calibrate`)",
    )
    taxonomy_model_file: str = _f(
        "",
        "model file (`rcbht train`) whose taxonomy profile labels the words; a profile that "
        "taxonomy_profile or taxonomy_config_file names must be that model's (empty: no model)",
    )
    stream_profile: StreamProfile = _f(
        "reference",
        "reference (words equal the batch engine's; whole-trial quantities are waited for), "
        "causal (past samples only: moment-axis words without waiting) or live (causal, and "
        "every word final within finality_bound_s of its end)",
    )
    stream_config_file: str = _f("", "optional YAML file overriding config/stream.yaml")
    qos_depth: int = _f(10000, QOS_DEPTH_HELP)
    qos_reliability: Reliability = _f("reliable", "reliable or best_effort")
    spin: Spin = _f(DEFAULT_SPIN, SPIN_HELP)
    pose_topics: tuple[str, ...] = _f(
        (),
        "geometry_msgs/PoseStamped of each arm's sensor in the world, in `arms` order, for "
        "intake.tool_mass_kg (empty: no gravity compensation)",
    )
    intake: IntakeConfig = field(default_factory=IntakeConfig)
    """Parameters `intake.<name>`: what happens to each sample before the RCBHT."""


@dataclass(frozen=True)
class ClassifierConfig:
    """classifier_node: words (+ applied sub-task events) -> belief and /task_state."""

    model_file: str = _f("", "model file written by `rcbht train` (empty: publish 'unknown')")
    mode: BeliefMode = _f("boundary", "boundary (words since the last sub-task event) or window")
    window_s: float = _f(2.0, "window mode: seconds of words the belief covers")
    publish_rate_hz: float = _f(
        10.0, "/task_state is also republished at this rate (0: only on change)"
    )
    arms: tuple[str, ...] = _f(("R",), "arm names whose words are classified, as in the segmenter")
    words_namespace: str = _f("rcbht", "namespace of the word topics, as in the segmenter")
    phase_topic: str = _f("rcbht/phase", "rcbht_interfaces/Phase events from the segmenter")
    state_topic: str = _f("/task_state", "std_msgs/String: the believed sub-task name")
    belief_topic: str = _f("rcbht/belief", "rcbht_interfaces/Belief: probabilities and window")
    end_phases: tuple[str, ...] = _f(("done",), "event names that end the task")
    expected_profile: str = _f("", "taxonomy profile the model must be trained with ('' = any)")
    qos_depth: int = _f(10000, QOS_DEPTH_HELP)
    qos_reliability: Reliability = _f("reliable", "reliable or best_effort")
    spin: Spin = _f(DEFAULT_SPIN, SPIN_HELP)
    teach_enabled: bool = _f(
        False,
        "learn labelled windows (service ~/teach, topic teach_topic) into the Mondrian model; "
        "a model_file that does not exist yet is a cold start ('unknown' until the first taught "
        "window)",
    )
    teach_file: str = _f(
        "", "each taught model is saved here, atomically ('': to model_file; both '': not saved)"
    )
    teach_history_s: float = _f(
        60.0,
        "teaching: stream seconds of words kept for labels given after the fact (besides the last "
        "finished sub-task)",
    )
    teach_topic: str = _f("rcbht/teach", "rcbht_interfaces/TeachRequest: fire-and-forget labels")
    teach_config_file: str = _f("", "YAML file with a `teach` section ('': config/teach.yaml)")
    state: TaskStateConfig = field(default_factory=TaskStateConfig)
    """Parameters `state.<name>`: when a new believed sub-task becomes /task_state."""


@dataclass(frozen=True)
class VerifierConfig:
    """verifier_node: wrench topics per arm + /task_phase -> verdicts and /task_health."""

    verifier_file: str = _f(
        "", "verifier file written by `rcbht verify-train` (empty: no verdicts, health 'unknown')"
    )
    arms: tuple[str, ...] = _f(("R",), "arm names, as in the segmenter (the verifier's arms)")
    wrench_topics: tuple[str, ...] = _f(
        ("/wrench",), "geometry_msgs/WrenchStamped topic of each arm, in `arms` order"
    )
    phase_topic: str = _f(
        "/task_phase", "std_msgs/String sub-task events of the task's state machine"
    )
    end_phases: tuple[str, ...] = _f(("done",), "event names that end the task (end the stream)")
    task_file: str = _f(
        "",
        "task.yaml naming the sub-tasks (empty: every event that is not an end phase starts one)",
    )
    event_hold_s: float = _f(0.2, "as segmenter_node's event_hold_s")
    event_max_hold_s: float = _f(10.0, "as segmenter_node's event_max_hold_s")
    belief_topic: str = _f(
        "rcbht/belief", "rcbht_interfaces/Belief of classifier_node: the verdicts' subtask field"
    )
    verdict_topic: str = _f("rcbht/verdict", "rcbht_interfaces/Verdict: one per tick")
    health_topic: str = _f(
        "/task_health",
        "std_msgs/String: nominal, anomaly or the failure class (latched; on change and at "
        "publish_rate_hz)",
    )
    publish_rate_hz: float = _f(
        10.0, "the health topic is also republished at this rate (0: only on change)"
    )
    qos_depth: int = _f(10000, QOS_DEPTH_HELP)
    qos_reliability: Reliability = _f("reliable", "reliable or best_effort")
    spin: Spin = _f(DEFAULT_SPIN, SPIN_HELP)


@dataclass(frozen=True)
class SimNodeConfig:
    """sim_node: the simulated snap cell as a robot: /wrench, /task_phase and ~/attempt."""

    sim_config: str = _f("", "simulator config file (empty: config/sim/cell.yaml)")
    recovery_file: str = _f(
        "", "recovery table whose bounds every attempt goal must keep (empty: the snap table)"
    )
    rate_factor: float = _f(1.0, "simulated seconds per wall-clock second (1: real time)")
    wrench_topic: str = _f("/wrench", "geometry_msgs/WrenchStamped of the arm's sensor")
    phase_topic: str = _f("/task_phase", "std_msgs/String sub-task events of the controller")
    frame_id: str = _f("r_ft", "frame of the published wrench")
    qos_depth: int = _f(10000, QOS_DEPTH_HELP)
    qos_reliability: Reliability = _f("reliable", "reliable or best_effort")
    spin: Spin = _f("executor", SPIN_HELP)


@dataclass(frozen=True)
class PlannerConfig:
    """planner_node: rcbht/verdict and the attempts' results -> attempts, aborts, decisions."""

    policy: Literal["none", "retry", "search", "introspect", "oracle"] = _f(
        "introspect", "none, retry, search, introspect or oracle (docs/closed-loop.md)"
    )
    recovery_file: str = _f("", "recovery table (empty: config/recovery/snap.yaml)")
    verifier_file: str = _f(
        "", "the verifier_node's file: its learnt correction sizes (empty: introspect runs retry)"
    )
    attempt_action: str = _f("/sim_node/attempt", "rcbht_interfaces/Attempt action server")
    verdict_topic: str = _f("rcbht/verdict", "rcbht_interfaces/Verdict of verifier_node")
    decision_topic: str = _f("rcbht/decision", "rcbht_interfaces/PlanDecision: every decision")
    qos_depth: int = _f(10000, QOS_DEPTH_HELP)
    qos_reliability: Reliability = _f("reliable", "reliable or best_effort")
    spin: Spin = _f("executor", SPIN_HELP)


NodeConfig = TypeVar(
    "NodeConfig",
    bound=SegmenterConfig | ClassifierConfig | VerifierConfig | SimNodeConfig | PlannerConfig,
)
"""The config of one node (the checks and the defaults file depend on which)."""
S = TypeVar("S")
"""A nested section of a node's config (its intake, its task state)."""


def descriptions(cls: type, prefix: str = "") -> dict[str, str]:
    """Parameter name -> description; a nested config's fields are `<field>.<name>`."""
    out = {}
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        kind = hints[f.name]
        if isinstance(kind, type) and dataclasses.is_dataclass(kind):
            out.update(descriptions(kind, f"{prefix}{f.name}."))
        else:
            out[prefix + f.name] = f.metadata.get("description", "")
    return out


def defaults(cls: type) -> dict[str, Any]:
    """Parameter name -> default value (lists for tuples, as ROS parameters want); a nested
    config's fields are `<field>.<name>`, as a ROS parameter file's nested mappings are."""
    out = {}

    def add(prefix: str, values: dict[str, Any]) -> None:
        for k, v in values.items():
            if isinstance(v, dict):
                add(f"{prefix}{k}.", v)
            else:
                out[prefix + k] = list(v) if isinstance(v, tuple) else v

    add("", dataclasses.asdict(cls()))
    return out


def nested(values: dict[str, Any]) -> dict[str, Any]:
    """Parameter values with dotted names (`intake.frozen_s`) as nested mappings."""
    out: dict[str, Any] = {}
    for name, value in values.items():
        *parents, leaf = name.split(".")
        node = out
        for part in parents:
            node = node.setdefault(part, {})
        if isinstance(value, dict) and isinstance(node.get(leaf), dict):
            node[leaf].update(value)
        else:
            node[leaf] = value
    return out


def word_topics(namespace: str, arms: tuple[str, ...]) -> dict[tuple[str, str], str]:
    """(arm, level topic) -> topic name: <ns>/<level> for one arm, <arm>/<ns>/<level> for two."""
    ns = namespace.strip("/")
    out = {}
    for arm in arms:
        prefix = ns if len(arms) == 1 else f"{arm}/{ns}"
        for level in LEVEL_TOPICS:
            out[(arm, level)] = f"{prefix}/{level}"
    return out


TOPIC_NAME = re.compile(r"(~/|/)?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")
"""A ROS topic name (relative, absolute or private): tokens of letters, digits and _."""
TOPIC_FIELDS = (
    "wrench_topics",
    "phase_topic",
    "words_namespace",
    "applied_phase_topic",
    "state_topic",
    "belief_topic",
    "pose_topics",
    "teach_topic",
    "verdict_topic",
    "health_topic",
    "wrench_topic",
    "decision_topic",
    "attempt_action",
)


def _check(cond: bool, field_name: str, message: str, path: Path | None) -> None:
    if not cond:
        raise InputError(message, path=path, field=field_name)


def _check_section(check: Callable[[S], object], section: S, name: str, path: Path | None) -> None:
    """A nested section's own check; its error names the field under `name` in this file."""
    try:
        check(section)
    except InputError as exc:
        raise InputError(exc.message, path=path, field=f"{name}.{exc.field}") from None


def validate(cfg: NodeConfig, path: Path | None = None) -> NodeConfig:
    """Checks beyond the field types (from_mapping checks those, Literal choices included);
    InputError names the parameter."""
    _check_common(cfg, path)
    if isinstance(cfg, SegmenterConfig | VerifierConfig):
        _check_wrench_intake(cfg, path)
    if isinstance(cfg, VerifierConfig):
        _check_verifier(cfg, path)
    if isinstance(cfg, SegmenterConfig):
        _check_segmenter(cfg, path)
    if isinstance(cfg, ClassifierConfig):
        _check_classifier(cfg, path)
    if isinstance(cfg, SimNodeConfig):
        _check(cfg.rate_factor > 0, "rate_factor", f"must be > 0, got {cfg.rate_factor}", path)
    return cfg


def _check_common(cfg: NodeConfig, path: Path | None) -> None:
    """The parameters every node has: arms (the robot's), QoS depth, topic names."""
    arms = getattr(cfg, "arms", ("R",))
    _check(1 <= len(arms) <= 2, "arms", f"expected one or two arms, got {list(arms)}", path)
    _check(
        len(set(arms)) == len(arms) and all(arms),
        "arms",
        "arm names must be unique and non-empty",
        path,
    )
    _check(cfg.qos_depth >= 1, "qos_depth", f"must be >= 1, got {cfg.qos_depth}", path)
    for name in TOPIC_FIELDS:
        values = getattr(cfg, name, ())
        for value in (values,) if isinstance(values, str) else values:
            if name == "words_namespace":  # a prefix: slashes around it do not matter
                value = value.strip("/") or "rcbht"
            _check(
                bool(TOPIC_NAME.fullmatch(value)),
                name,
                f"not a valid ROS topic name: {value!r}",
                path,
            )


def _check_wrench_intake(cfg: SegmenterConfig | VerifierConfig, path: Path | None) -> None:
    """The nodes that read the robot's wrench and sub-task events: topics, event holds, files."""
    arms = cfg.arms
    _check(
        len(cfg.wrench_topics) == len(arms),
        "wrench_topics",
        f"expected one topic per arm ({len(arms)}), got {len(cfg.wrench_topics)}",
        path,
    )
    _check(bool(cfg.phase_topic), "phase_topic", "must not be empty", path)
    _check(
        0 < cfg.event_hold_s <= 10,
        "event_hold_s",
        f"must be in (0, 10], got {cfg.event_hold_s}",
        path,
    )
    _check(
        cfg.event_hold_s <= cfg.event_max_hold_s <= 600,
        "event_max_hold_s",
        f"must be in [event_hold_s, 600], got {cfg.event_max_hold_s}",
        path,
    )
    for name in ("taxonomy_config_file", "taxonomy_model_file", "stream_config_file", "task_file"):
        value = getattr(cfg, name, "")
        _check(not value or Path(value).is_file(), name, f"no such file: {value}", path)


def segmenter_taxonomy(cfg: SegmenterConfig) -> TaxonomyConfig:
    """The profile segmenter_node labels with: the one taxonomy_profile / taxonomy_config_file
    name, else the one taxonomy_model_file embeds, else reference; refused when not the model's."""
    named = bool(cfg.taxonomy_profile or cfg.taxonomy_config_file)
    given = load_taxonomy_config(cfg.taxonomy_profile or None, cfg.taxonomy_config_file or None)
    if not cfg.taxonomy_model_file:
        return given
    # imported here: a node without a model file needs no skops (the model file's SVM)
    from rcbht_introspection.learn.model_file import model_file_taxonomy

    return model_file_taxonomy(cfg.taxonomy_model_file, given if named else None)


def task_events(cfg: SegmenterConfig | VerifierConfig) -> tuple[tuple[str, ...], Task | None]:
    """The events that end the task (the node's and its task file's) and the task file's Task."""
    task = load_task_file(cfg.task_file) if cfg.task_file else None
    ends = dict.fromkeys([*cfg.end_phases, *(task.end_phases if task else ())])
    return tuple(ends), task


def _check_verifier(cfg: VerifierConfig, path: Path | None) -> None:
    """verifier_node's own parameters: verdict rate, health topic."""
    _check(
        0 <= cfg.publish_rate_hz <= 1000,
        "publish_rate_hz",
        f"must be 0..1000, got {cfg.publish_rate_hz}",
        path,
    )
    _check(bool(cfg.health_topic), "health_topic", "must not be empty", path)


def _check_segmenter(cfg: SegmenterConfig, path: Path | None) -> None:
    """segmenter_node's own parameters: pose topics (gravity compensation), the intake."""
    arms = cfg.arms
    _check(
        len(cfg.pose_topics) in (0, len(arms)),
        "pose_topics",
        f"expected none or one topic per arm ({len(arms)}), got {len(cfg.pose_topics)}",
        path,
    )
    _check(
        bool(cfg.pose_topics) == cfg.intake.compensates_gravity,
        "pose_topics",
        "gravity compensation needs both intake.tool_mass_kg > 0 and a pose topic per arm"
        f" (tool_mass_kg {cfg.intake.tool_mass_kg}, pose_topics {list(cfg.pose_topics)})",
        path,
    )
    _check_section(check_intake, cfg.intake, "intake", path)


def _check_classifier(cfg: ClassifierConfig, path: Path | None) -> None:
    """classifier_node's own parameters: window, rate, task state, teaching."""
    _check(cfg.window_s > 0, "window_s", f"must be > 0, got {cfg.window_s}", path)
    _check(
        0 <= cfg.publish_rate_hz <= 1000,
        "publish_rate_hz",
        f"must be 0..1000, got {cfg.publish_rate_hz}",
        path,
    )
    _check_section(check_task_state, cfg.state, "state", path)
    _check(bool(cfg.state_topic), "state_topic", "must not be empty", path)
    _check(
        0 <= cfg.teach_history_s <= 3600,
        "teach_history_s",
        f"must be in [0, 3600], got {cfg.teach_history_s}",
        path,
    )
    _check(
        not cfg.teach_config_file or Path(cfg.teach_config_file).is_file(),
        "teach_config_file",
        f"no such file: {cfg.teach_config_file}",
        path,
    )


def config_from_parameters(
    cls: type[NodeConfig], values: dict[str, Any], path: Path | None = None
) -> NodeConfig:
    """Typed, validated config from parameter values (unknown names and bad types are errors)."""
    return validate(from_mapping(cls, nested(values), path=path), path)


NODE_NAMES: dict[type, str] = {
    SegmenterConfig: "segmenter_node",
    ClassifierConfig: "classifier_node",
    VerifierConfig: "verifier_node",
    SimNodeConfig: "sim_node",
    PlannerConfig: "planner_node",
}
CONFIG_FILES: dict[type, str] = {
    SegmenterConfig: "segmenter.yaml",
    ClassifierConfig: "classifier.yaml",
    VerifierConfig: "verifier.yaml",
    SimNodeConfig: "sim_node.yaml",
    PlannerConfig: "planner.yaml",
}


def load_node_config(cls: type[NodeConfig], path: Path | str | None = None) -> NodeConfig:
    """Config of a node from a ROS parameter file (default: config/<node>.yaml).

    The parameters are `<node>: ros__parameters: {...}` (or under the wildcard `/**`), the layout
    `--params-file` takes; errors name the file, line and parameter.
    """
    path = Path(path) if path is not None else config_path(CONFIG_FILES[cls])
    document = read_yaml(path)
    node = NODE_NAMES[cls]
    if isinstance(document, dict) and node not in document and "/**" in document:
        node = "/**"
    return config_from_document(
        cls, document, path=path, section=(node, "ros__parameters"), check=validate
    )

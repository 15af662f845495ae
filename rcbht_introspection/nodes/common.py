"""What the nodes share: QoS, parameters, the managed (lifecycle) node, /diagnostics, run()."""

from __future__ import annotations

import sys
import time
import traceback
from collections.abc import Callable, Iterable
from functools import partial
from typing import Any, Protocol

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.context import Context
from rclpy.executors import Executor, ShutdownException, SingleThreadedExecutor, TimeoutException
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription
from rclpy.utilities import try_shutdown

from rcbht_introspection.configure.params import (
    ClassifierConfig,
    NodeConfig,
    PlannerConfig,
    Reliability,
    SegmenterConfig,
    SimNodeConfig,
    VerifierConfig,
    config_from_parameters,
    defaults,
    descriptions,
)
from rcbht_introspection.configure.spin import Spin
from rcbht_introspection.errors import InputError
from rcbht_introspection.lifetime import StopSignal, keep_out_of_collector
from rcbht_introspection.live.health import ERROR, Health
from rcbht_introspection.messages import diagnostic_array


def qos_profile(depth: int, reliability: Reliability) -> QoSProfile:
    """Keep-last QoS of `depth`, reliable or best effort."""
    return QoSProfile(  # type: ignore[no-untyped-call]  # rclpy's QoSProfile takes **kwargs
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE
        if reliability == "reliable"
        else ReliabilityPolicy.BEST_EFFORT,
    )


PHASE_HISTORY = 16
"""Applied sub-task events a late-joining subscriber still receives (one task has five)."""


def phase_qos(reliability: Reliability) -> QoSProfile:
    """QoS of the applied sub-task events (rcbht/phase): latched, like a static transform.

    A classifier that starts (or matches) after a sub-task event still gets the current task's
    boundaries; without them it would wait forever for verdicts on sub-tasks it never saw.
    """
    qos = qos_profile(PHASE_HISTORY, reliability)
    qos.durability = DurabilityPolicy.TRANSIENT_LOCAL
    return qos


def declare_parameters(node: Node, cls: type) -> None:
    """Declare one parameter per config field (with its description); configure reads them."""
    texts = descriptions(cls)
    for name, default in defaults(cls).items():
        # an empty list has no element type for rclpy to infer (it would take bytes): such a
        # parameter takes any type, and the config's own check (read_config) types it
        untyped = isinstance(default, list) and not default
        node.declare_parameter(
            name, default, ParameterDescriptor(description=texts[name], dynamic_typing=untyped)
        )


def read_config(node: Node, cls: type[NodeConfig]) -> NodeConfig:
    """The validated config from the node's current parameter values (InputError names one)."""
    values = {name: node.get_parameter(name).value for name in defaults(cls)}
    return config_from_parameters(cls, values)


class Inputs(Protocol):
    """A node's intake (nodes/intake.py): what arrived is handed over at `settled()`."""

    def settled(self) -> None:
        """Hand what arrived to the session, in publication order."""

    def publishers(self) -> int:
        """Fewest publishers matched on any intake topic."""


class NodeLogger(Protocol):
    """What the nodes call on their logger (rclpy's RcutilsLogger, which has no annotations)."""

    def info(self, message: str) -> bool:
        """Log `message` at INFO; whether it was logged."""

    def warning(self, message: str, *, throttle_duration_sec: float = ...) -> bool:
        """Log `message` at WARN (at most once per `throttle_duration_sec`); whether it was."""

    def error(self, message: str) -> bool:
        """Log `message` at ERROR; whether it was logged."""


def log_notes(logger: NodeLogger, notes: Iterable[tuple[str, str]]) -> None:
    """Log (level, line) notes, each severity from its own call: rclpy fixes a call site's
    severity at its first call and raises ValueError in the callback at another one."""
    for level, line in notes:
        if level == "info":
            logger.info(line)
        elif level == "warning":
            logger.warning(line)
        else:
            logger.error(line)


DIAGNOSTICS_PERIOD_S = 1.0
"""How often a node publishes its status on /diagnostics."""


def source_ns(info: Any) -> int | None:
    """The DDS source timestamp of rclpy's MessageInfo (None when the middleware has none)."""
    return (info.get("source_timestamp") if info else None) or None


def _with_info(handler: Callable[[Any, int | None], None], msg: Any, info: Any) -> None:
    handler(msg, source_ns(info))


def _without_info(handler: Callable[[Any, int | None], None], msg: Any) -> None:
    handler(msg, None)


class ManagedNode(LifecycleNode):
    """A lifecycle node of ours: configure reads and validates the parameters of `config_class`.

    Subclasses build their state and publishers in `configure` and subscribe in `activate`;
    what each created is destroyed after `deactivate` (which logs the statistics line) and
    `cleanup`. Parameters can change while the node is not active; they take effect at the next
    configure (deactivate -> cleanup -> configure -> activate reloads a model file). The status
    of `health()` goes to /diagnostics once a second in every state.
    """

    def __init__(
        self,
        name: str,
        config_class: type[
            SegmenterConfig | ClassifierConfig | VerifierConfig | SimNodeConfig | PlannerConfig
        ],
    ) -> None:
        super().__init__(name)
        self.config_class = config_class
        declare_parameters(self, config_class)
        autostart = self.declare_parameter(
            "autostart",
            True,
            ParameterDescriptor(
                description="configure and activate at start-up, without a manager"
            ),
        )
        self.autostart = bool(autostart.value)
        self.state_label = "unconfigured"
        self.config_error = ""
        self.events = False
        """Spun by rclpy's EventsExecutor (run() decides at start-up): callbacks get the
        message alone, no MessageInfo (rclpy 7.1.6's EventsExecutor cannot pass it)."""
        self.inputs: Inputs | None = None
        """The wrench and /task_phase subscriptions while active (segmenter, verifier)."""
        self.created: dict[str, set[int]] = {}
        """The entities each transition created (configure, activate), until it is undone."""
        self.stop: StopSignal | None = None
        """The process's stop request (set by run()); a manager's shutdown transition sets it."""
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._diag_time = time.monotonic()
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._publish_diagnostics)

    # --- what a node implements -------------------------------------------------------------

    def configure(self, cfg: Any) -> None:
        """Build the state and the publishers from a validated config."""

    def activate(self) -> None:
        """Subscribe: input flows from now on."""

    def deactivate(self) -> None:
        """Log the statistics line (then what activate created is destroyed)."""

    def cleanup(self) -> None:
        """Drop what configure built beside its entities (which are destroyed after it)."""

    def health(self, period_s: float) -> list[Health]:
        """Statuses for /diagnostics covering the last `period_s` seconds."""
        return []

    def settled(self) -> None:
        """The executor ran what was delivered: the robot's intake hands it over in
        publication order."""
        if self.inputs is not None:
            self.inputs.settled()

    def subscribe(
        self,
        msg_type: Any,
        topic: str,
        handler: Callable[[Any, int | None], None],
        qos: QoSProfile,
        **kwargs: Any,
    ) -> Subscription:
        """A subscription whose `handler(msg, source_ns)` gets the DDS source timestamp, or None
        under the EventsExecutor (which calls a subscription's callback with the message only)."""
        wrap = _without_info if self.events else _with_info
        callback: Callable[..., None] = partial(wrap, handler)
        return self.create_subscription(msg_type, topic, callback, qos, **kwargs)

    def log_notes(self, notes: Iterable[tuple[str, str]]) -> None:
        """Log what the core noted: (level info, warning or error; one line) each."""
        log_notes(self.get_logger(), notes)

    def get_logger(self) -> NodeLogger:
        """The node's logger: rclpy's Node.get_logger, seen through the typed NodeLogger."""
        logger: NodeLogger = super().get_logger()  # type: ignore[no-untyped-call]
        return logger

    # --- lifecycle ----------------------------------------------------------------------------
    # rclpy turns an exception in a transition callback into a silent ERROR transition; each
    # transition here therefore catches it, logs one line, removes the entities the failed step
    # created and reports FAILURE (the node stays in the state it was in). What `configure`
    # creates is destroyed after `cleanup`, what `activate` creates after `deactivate`.
    def _transition(
        self, name: str, step: Callable[[], None], then: str
    ) -> TransitionCallbackReturn:
        before = self._entities()
        try:
            step()
        except Exception as exc:
            self.config_error = (
                f"{name} failed: {exc}" if not isinstance(exc, InputError) else str(exc)
            )
            self.get_logger().error(
                f"{name} failed: {exc}"
                if isinstance(exc, InputError)
                else f"{name} failed: {type(exc).__name__}: {exc}\n{traceback.format_exc()}"
            )
            self._destroy(self._entities() - before)
            return TransitionCallbackReturn.FAILURE
        self.created[name] = self._entities() - before
        self.config_error = ""
        self.state_label = then
        return TransitionCallbackReturn.SUCCESS

    def _entities(self) -> set[int]:
        kinds = (self.publishers, self.subscriptions, self.timers, self.services)
        return {id(e) for kind in kinds for e in kind}

    def _destroy(self, ids: set[int]) -> None:
        """Destroy the publishers, subscriptions, timers and services among `ids`."""
        for sub in [s for s in self.subscriptions if id(s) in ids]:
            self.destroy_subscription(sub)
        for timer in [t for t in self.timers if id(t) in ids]:
            self.destroy_timer(timer)
        for pub in [p for p in self.publishers if id(p) in ids]:
            self.destroy_publisher(pub)
        for srv in [s for s in self.services if id(s) in ids]:
            self.destroy_service(srv)

    def _undo(self, name: str) -> None:
        """Destroy what the transition `name` created."""
        self._destroy(self.created.pop(name, set()))
        if name == "activate":
            self.inputs = None

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        return self._transition("configure", self._configure, "inactive")

    def _configure(self) -> None:
        self.configure(read_config(self, self.config_class))

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        result = self._transition("activate", self.activate, "active")
        if result == TransitionCallbackReturn.SUCCESS:
            return super().on_activate(state)
        return result

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        result = self._transition("deactivate", self.deactivate, "inactive")
        if result == TransitionCallbackReturn.SUCCESS:
            self._undo("activate")
            return super().on_deactivate(state)
        return result

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        result = self._transition("cleanup", self.cleanup, "unconfigured")
        if result == TransitionCallbackReturn.SUCCESS:
            self._undo("configure")
        return result

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        if self.state_label == "active":
            self._transition("deactivate", self.deactivate, "inactive")
            self._undo("activate")
        if self.state_label == "inactive":
            self._transition("cleanup", self.cleanup, "unconfigured")
            self._undo("configure")
        self.state_label = "finalized"
        if self.stop is not None:  # a manager shut the node down: the process ends too
            self.stop.request()
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        # only reachable when code outside _transition raised: rclpy finalizes the node
        self.get_logger().error(f"a lifecycle transition failed in state {self.state_label}")
        self._destroy(self.created.pop("activate", set()) | self.created.pop("configure", set()))
        self.state_label = "finalized"
        if self.stop is not None:
            self.stop.request()
        return TransitionCallbackReturn.FAILURE

    def finish(self) -> None:
        """The process ends: shut down from whatever state the node is in (logs its statistics)."""
        if self.state_label != "finalized":
            try:
                self.trigger_shutdown()  # type: ignore[no-untyped-call]
            except RuntimeError as exc:  # rclpy's state machine refused (RCLError)
                self.get_logger().error(f"shutdown transition refused: {exc}")

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        if self.state_label == "active":
            return SetParametersResult(
                successful=False,
                reason="parameters take effect at configure: deactivate and clean up first",
            )
        return SetParametersResult(successful=True)

    def _publish_diagnostics(self) -> None:
        now = time.monotonic()
        period, self._diag_time = now - self._diag_time, now
        statuses = self.health(period) if self.state_label in ("inactive", "active") else []
        if self.config_error:
            statuses.insert(0, Health(f"{self.get_name()}: configure", ERROR, self.config_error))
        if not statuses:
            statuses.append(Health(f"{self.get_name()}: lifecycle", 0, self.state_label))
        self.diagnostics_pub.publish(diagnostic_array(statuses, self.get_clock().now().to_msg()))


def run(
    node_factory: Callable[[], ManagedNode], name: str, args: list[str] | None, stop: StopSignal
) -> int:
    """Create the node, bring it up (autostart), spin it until `stop`, shut it down in order.

    rclpy's signal handlers are not installed: SIGINT/SIGTERM only set `stop` (lifetime.py),
    so the context stays valid until the node has shut down and logged its last line.
    """
    if stop.requested:  # stopped while the modules were imported: nothing was started
        stop.exiting()
        return 0
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    executor = None
    try:
        node = node_factory()
        node.stop = stop
        executor, node.events = make_executor(str(node.get_parameter("spin").value))
        executor.add_node(node)
        node.get_logger().info(f"spun by rclpy's {type(executor).__name__}")
        if node.autostart and not stop.requested:
            configured = node.trigger_configure() == TransitionCallbackReturn.SUCCESS  # type: ignore[no-untyped-call]
            if configured:
                stop.up()  # a stop from here shuts the node down in order (statistics line)
            if not configured or node.trigger_activate() != TransitionCallbackReturn.SUCCESS:  # type: ignore[no-untyped-call]
                # one line naming the parameter; the node never started
                print(f"[{name}] error: {node.config_error}", file=sys.stderr, flush=True)
                return 2
        stop.up()
        keep_out_of_collector()  # start-up objects: rclpy, NumPy, scikit-learn, the model
        spin(executor, node, stop)
    finally:
        if node is not None:
            node.finish()
        if executor is not None:
            executor.shutdown(timeout_sec=0)  # releases what its last wait still holds
        if node is not None:
            node.destroy_node()  # type: ignore[no-untyped-call]
        try_shutdown()
        stop.exiting()
    return 0


def make_executor(spin: Spin | str, context: Context | None = None) -> tuple[Executor, bool]:
    """The process's executor for the parameter `spin` (read at start-up) and whether it is
    rclpy's EventsExecutor: that one for `events` where rclpy has it, else SingleThreadedExecutor."""
    if spin == "events":
        try:
            from rclpy.experimental.events_executor import EventsExecutor
        except ImportError:  # an rclpy without the experimental executor
            return SingleThreadedExecutor(context=context), False
        return EventsExecutor(context=context), True
    return SingleThreadedExecutor(context=context), False


SPIN_WAIT_S = 0.02
"""Longest wait of the spin for work: a stop request is seen within it."""
BURST_CALLBACKS = 10_000
"""Most callbacks the SingleThreadedExecutor runs before the node is told its burst is done."""


def spin(executor: Executor, node: ManagedNode, stop: StopSignal) -> None:
    """Spin `node` until `stop`: spin_once, then (SingleThreadedExecutor) every callback
    delivered by then, then `settled()` hands what arrived to the session in publication order.
    Not executor.spin(): rclpy 7.1's EventsExecutor cannot be ended from inside, and a guard
    condition to mark a burst's end cost more (docs/ros.md, Spinning)."""
    while executor.context.ok() and not stop.requested:
        executor.spin_once(timeout_sec=SPIN_WAIT_S)
        if not node.events:
            serve_ready(executor, BURST_CALLBACKS)
        node.settled()


def serve_ready(executor: Executor, limit: int) -> int:
    """Run up to `limit` callbacks the executor finds ready now, without blocking; how many ran."""
    for done in range(limit):
        try:
            handler, _, _ = executor.wait_for_ready_callbacks(timeout_sec=0)
        except (TimeoutException, ShutdownException):
            return done
        handler()
        error = handler.exception()  # type: ignore[no-untyped-call]  # rclpy's Task is untyped
        if error is not None:
            raise error
    return limit

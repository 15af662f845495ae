"""What both nodes share: QoS from the config, parameter declaration, spinning with clean SIGINT."""

from __future__ import annotations

import contextlib
import faulthandler
import gc
import signal
import sys
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol, TypeVar, runtime_checkable

import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.callback_groups import CallbackGroup
from rclpy.executors import (
    ExternalShutdownException,
    SingleThreadedExecutor,
    TimeoutException,
)
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerGuardCondition
from rclpy.subscription import Subscription

from rcbht_introspection.errors import InputError
from rcbht_introspection.nodes.params import config_from_parameters, defaults, descriptions

T = TypeVar("T")


def qos_profile(depth: int, reliability: str) -> QoSProfile:
    """Keep-last QoS of `depth`, reliable or best effort."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE
        if reliability == "reliable"
        else ReliabilityPolicy.BEST_EFFORT,
    )


PHASE_HISTORY = 16
"""Applied sub-task events a late-joining subscriber still receives (one task has five)."""


def phase_qos(reliability: str) -> QoSProfile:
    """QoS of the applied sub-task events (rcbht/phase): latched, like a static transform.

    A classifier that starts (or matches) after a sub-task event still gets the current task's
    boundaries; without them it would wait forever for verdicts on sub-tasks it never saw.
    """
    qos = qos_profile(PHASE_HISTORY, reliability)
    qos.durability = DurabilityPolicy.TRANSIENT_LOCAL
    return qos


def declare_config(node: Node, cls: type[T]) -> T:
    """Declare one read-only parameter per config field and return the validated config."""
    texts = descriptions(cls)
    values: dict[str, Any] = {}
    for name, default in defaults(cls).items():
        descriptor = ParameterDescriptor(description=texts[name], read_only=True)
        param = node.declare_parameter(name, default, descriptor)
        values[name] = param.value
    return config_from_parameters(cls, values)


HOUSEKEEPING_S = 0.02
"""How often a draining node's other entities (parameter services, QoS events) are served."""
HOUSEKEEPING_CALLBACKS = 16
"""Most executor callbacks served per housekeeping round (the hot inputs must not wait long)."""


class DrainedGroup(CallbackGroup):
    """Callback group of subscriptions that `spin_draining` takes itself; the executor skips them.

    Their QoS-event handlers (incompatible QoS, lost messages) still run through the executor.
    """

    def can_execute(self, entity: object) -> bool:
        return not isinstance(entity, Subscription)

    def beginning_execution(self, entity: object) -> bool:
        return not isinstance(entity, Subscription)

    def ending_execution(self, entity: object) -> None:
        pass


@runtime_checkable
class Draining(Protocol):
    """A node whose high-rate inputs (subscriptions in a DrainedGroup) are taken by `drain`."""

    def drain(self) -> None:
        """Take and handle every message already delivered on the drained subscriptions."""


def take(sub: Subscription) -> tuple[Any, Any] | None:
    """The next delivered message of `sub` as (message, info), or None: what drain() loops on."""
    with sub.handle:
        return sub.handle.take_message(sub.msg_type, sub.raw)


def serve_ready(executor: SingleThreadedExecutor, limit: int) -> None:
    """Run up to `limit` callbacks the executor finds ready now, without blocking."""
    for _ in range(limit):
        try:
            handler, _, _ = executor.wait_for_ready_callbacks(timeout_sec=0)
        except TimeoutException:
            return
        handler()
        if handler.exception() is not None:
            raise handler.exception()


def spin_draining(executor: SingleThreadedExecutor, node: Node) -> None:
    """Wait on the drained subscriptions and timers with one small wait set; drain on each wake-up.

    rclpy's executor rebuilds a wait set over every entity of the node (parameter services,
    QoS events, ...) on each wake-up: ~0.3 ms of CPU per 1 kHz sample. This loop is rclpy's own
    `wait_for_message` pattern; timers and the rest still run through the executor, when a timer
    is due and at least every HOUSEKEEPING_S.
    """
    context = executor.context
    if not isinstance(node, Draining):
        raise TypeError(f"{type(node).__name__} has no drain()")
    subs = [sub for sub in node.subscriptions if isinstance(sub.callback_group, DrainedGroup)]
    timers = list(node.timers)
    sigint = SignalHandlerGuardCondition(context)
    wait_set = _rclpy.WaitSet(len(subs), 1, len(timers), 0, 0, 0, context.handle)
    timeout_ns = int(HOUSEKEEPING_S * 1e9)
    due = time.monotonic()
    try:
        with contextlib.ExitStack() as handles:
            for entity in (*subs, *timers, sigint):
                handles.enter_context(entity.handle)
            while context.ok():
                wait_set.clear_entities()
                for sub in subs:
                    wait_set.add_subscription(sub.handle)
                for timer in timers:
                    wait_set.add_timer(timer.handle)
                wait_set.add_guard_condition(sigint.handle)
                wait_set.wait(timeout_ns)
                if not context.ok():
                    break
                node.drain()
                now = time.monotonic()
                if now >= due or wait_set.get_ready_entities("timer"):
                    due = now + HOUSEKEEPING_S
                    serve_ready(executor, HOUSEKEEPING_CALLBACKS)
        raise ExternalShutdownException()
    finally:
        sigint.destroy()


def _stop_quietly(signum: int, frame: object) -> None:
    """Python's part of SIGINT: nothing. rclpy's handler shuts the context down and wakes the node."""


def run(node_factory: Callable[[], Node], name: str, args: list[str] | None = None) -> int:
    """Create the node, spin it until SIGINT/SIGTERM, shut down cleanly.

    A `Draining` node is spun by `spin_draining`, any other by a SingleThreadedExecutor.
    """
    # rclpy chains SIGINT to Python's handler, whose KeyboardInterrupt can surface inside an
    # executor callback and leave rclpy objects half released (a classifier segfaulted at exit
    # once in ~30 replay runs); the node stops where its spin sees the context shut down instead
    signal.signal(signal.SIGINT, _stop_quietly)
    faulthandler.enable()  # a crash in native code leaves the Python stack in the node log
    rclpy.init(args=args)
    node = None
    executor = None
    code = 0
    try:
        node = node_factory()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        # start-up objects (rclpy, NumPy, scikit-learn, the model) live until exit: keep them
        # out of the cyclic collector, whose full passes over them stall a 1 kHz callback
        gc.collect()
        gc.freeze()
        if isinstance(node, Draining):
            spin_draining(executor, node)
        else:
            executor.spin()
    except InputError as exc:
        # one line naming the parameter; the node never started
        print(f"[{name}] error: {exc}", file=sys.stderr, flush=True)
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if executor is not None:
            executor.shutdown(timeout_sec=0)  # releases what its last wait still holds
        if node is not None:
            closer = getattr(node, "close", None)
            if closer is not None:
                closer()
            node.destroy_node()
        rclpy.try_shutdown()
    return code


class RosSession:
    """An rclpy context + node spun by a background SingleThreadedExecutor (for CLI tools).

    Signal handlers stay Python's, so Ctrl-C raises KeyboardInterrupt in the caller.
    """

    def __init__(self, name: str, domain_id: int | None = None) -> None:
        from rclpy.context import Context
        from rclpy.signals import SignalHandlerOptions

        self.context = Context()
        kwargs: dict[str, Any] = {"context": self.context}
        if domain_id is not None:
            kwargs["domain_id"] = domain_id
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO, **kwargs)
        self.node = Node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        with contextlib.suppress(Exception):  # the context was shut down under it
            self.executor.spin()

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=2.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self._thread.join(timeout=2.0)

    def __enter__(self) -> RosSession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

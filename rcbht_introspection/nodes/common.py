"""What both nodes share: QoS from the config, parameter declaration, spinning with clean SIGINT."""

from __future__ import annotations

import contextlib
import gc
import sys
import threading
from collections.abc import Callable
from typing import Any, TypeVar

import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

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


def declare_config(node: Node, cls: type[T]) -> T:
    """Declare one read-only parameter per config field and return the validated config."""
    texts = descriptions(cls)
    values: dict[str, Any] = {}
    for name, default in defaults(cls).items():
        descriptor = ParameterDescriptor(description=texts[name], read_only=True)
        param = node.declare_parameter(name, default, descriptor)
        values[name] = param.value
    return config_from_parameters(cls, values)


def run(node_factory: Callable[[], Node], name: str, args: list[str] | None = None) -> int:
    """Create the node, spin a SingleThreadedExecutor until SIGINT/SIGTERM, shut down cleanly."""
    rclpy.init(args=args)
    node = None
    code = 0
    try:
        node = node_factory()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        # start-up objects (rclpy, NumPy, scikit-learn, the model) live until exit: keep them
        # out of the cyclic collector, whose full passes over them stall a 1 kHz callback
        gc.collect()
        gc.freeze()
        executor.spin()
    except InputError as exc:
        # one line naming the parameter; the node never started
        print(f"[{name}] error: {exc}", file=sys.stderr, flush=True)
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
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

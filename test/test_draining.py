"""nodes/draining.py uses rclpy's private WaitSet / take_message API: checked here, in one process."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from ros_support import require_ros, ros_env

from rcbht_introspection.waiting import wait_until

pytestmark = pytest.mark.ros


def test_the_private_api_is_the_verified_rclpy_release() -> None:
    """A new rclpy pin must be re-verified against draining.py (then update VERIFIED_RCLPY)."""
    require_ros()
    from importlib.metadata import version

    from rcbht_introspection.nodes.draining import VERIFIED_RCLPY

    assert version("ros-rclpy") == VERIFIED_RCLPY


def test_spin_draining_follows_subscriptions_made_and_destroyed_while_it_spins(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Messages are drained, timers served, and a subscription created later is waited on too."""
    require_ros()
    for key, value in ros_env(tmp_path).items():
        monkeypatch.setenv(key, value)
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.signals import SignalHandlerOptions
    from std_msgs.msg import String

    from rcbht_introspection.nodes.draining import DrainedGroup, spin_draining, take
    from rcbht_introspection.nodes.lifetime import StopSignal

    context = Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)

    class Probe(Node):
        def __init__(self) -> None:
            super().__init__("probe", context=context)
            self.got: list[str] = []
            self.ticks = 0
            self.subs = []
            self.create_timer(0.01, self.tick)

        def tick(self) -> None:
            self.ticks += 1
            if self.ticks == 5:  # as a lifecycle activate would, from an executor callback
                sub = self.create_subscription(
                    String, "/probe_in", lambda m: None, 100, callback_group=DrainedGroup()
                )
                self.subs.append(sub)
            if len(self.got) == 20 and self.subs:  # all taken: destroy it under the spin
                self.destroy_subscription(self.subs.pop())

        def drain(self) -> None:
            for sub in self.subs:
                while (taken := take(sub)) is not None:
                    self.got.append(taken[0].data)

    node = Probe()
    sender = Node("sender", context=context)
    pub = sender.create_publisher(String, "/probe_in", 100)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    stop = StopSignal(watchdog_s=0)
    spinner = threading.Thread(target=spin_draining, args=(executor, node, stop))
    spinner.start()
    try:
        deadline = time.monotonic() + 20  # for all the waits below

        def wait(condition: Callable[[], object]) -> None:
            wait_until(condition, deadline - time.monotonic(), poll=0.01)

        wait(lambda: pub.get_subscription_count() > 0)
        for i in range(20):
            pub.publish(String(data=str(i)))
        wait(lambda: len(node.got) >= 20)
        assert node.got == [str(i) for i in range(20)]
        wait(lambda: not node.subs)
        assert not node.subs  # destroyed while the spin held its handle; the spin goes on
        ticks = node.ticks
        wait(lambda: node.ticks >= ticks + 5)
        assert node.ticks >= ticks + 5
        stop.request()
        spinner.join(5)
        assert not spinner.is_alive()
    finally:
        stop.request()
        spinner.join(5)
        executor.shutdown(timeout_sec=0)
        node.destroy_node()
        sender.destroy_node()
        rclpy.try_shutdown(context=context)


def test_without_the_private_api_a_draining_node_spins_on_rclpy_s_executor(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`spin: draining` where rclpy lacks the private wait set: the node configures, says why
    in one line, and takes its input through rclpy's executor (the public path)."""
    require_ros()
    for key, value in ros_env(tmp_path).items():
        monkeypatch.setenv(key, value)
    import rclpy
    from rclpy.impl.implementation_singleton import rclpy_implementation
    from rclpy.lifecycle import TransitionCallbackReturn
    from rclpy.parameter import Parameter
    from rclpy.signals import SignalHandlerOptions

    from rcbht_introspection.nodes import draining
    from rcbht_introspection.nodes.segmenter_node import SegmenterNode

    def drains() -> bool:
        node = SegmenterNode()
        try:
            [result] = node.set_parameters([Parameter("spin", value="draining")])
            assert result.successful, result.reason
            assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
            assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
            assert node.inputs is not None and node.inputs.draining == node.draining
            return node.draining
        finally:
            node.destroy_node()

    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    try:
        assert draining.unavailable() is None
        assert drains()
        monkeypatch.delattr(rclpy_implementation, "WaitSet")
        assert draining.unavailable() == "rclpy's private API has no WaitSet"
        assert not drains()
    finally:
        rclpy.try_shutdown()

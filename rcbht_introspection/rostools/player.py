"""Bag playback and raw recording over rclpy (stand-ins for `ros2 bag play` / `ros2 bag record`)."""

from __future__ import annotations

import importlib
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.bags import BagMessage, BagWriter
from rcbht_introspection.lifetime import StopSignal, keep_out_of_collector
from rcbht_introspection.waiting import wait_until


def message_class(msgtype: str) -> type:
    """Python class of 'pkg/msg/Type' (the package must be installed)."""
    pkg, kind, name = msgtype.split("/")
    try:
        cls: type = getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    except (ImportError, AttributeError):
        raise InputError(f"message type {msgtype} is not installed") from None
    return cls


class BagPlayer:
    """Publishes bag messages (raw CDR, no deserialisation) with their recorded timing / rate."""

    def __init__(self, node: Node, qos: QoSProfile | int = 1000) -> None:
        self.node = node
        self.qos = qos
        self.publishers: dict[str, Publisher] = {}

    def publisher(self, topic: str, msgtype: str) -> Publisher:
        pub = self.publishers.get(topic)
        if pub is None:
            pub = self.node.create_publisher(message_class(msgtype), topic, self.qos)
            self.publishers[topic] = pub
        return pub

    def prepare(self, messages: Sequence[BagMessage]) -> None:
        """Create every publisher the messages need (do it early: discovery takes time)."""
        for m in messages:
            self.publisher(m.topic, m.msgtype)

    def wait_for_subscribers(
        self, topics: Sequence[str], timeout: float = 20.0, stop: StopSignal | None = None
    ) -> bool:
        """True once each of `topics` has a matched subscriber."""
        pubs = [self.publishers[t] for t in topics if t in self.publishers]
        return wait_until(
            lambda: all(p.get_subscription_count() > 0 for p in pubs),
            timeout,
            stop=stop,
        )

    def wait_for_acks(self, timeout: float, stop: StopSignal | None = None) -> bool:
        """True once every reliable subscriber acknowledged everything published.

        One deadline for all publishers, checked in short steps, so a stop request ends it.
        """
        deadline = time.monotonic() + timeout
        step = Duration(nanoseconds=50_000_000)
        for pub in self.publishers.values():
            while not pub.wait_for_all_acked(step):
                if time.monotonic() > deadline or (stop is not None and stop.requested):
                    return False
        return True

    def play(
        self,
        messages: Sequence[BagMessage],
        rate: float = 1.0,
        on_publish: Callable[[BagMessage, int], None] | None = None,
        stop: threading.Event | StopSignal | None = None,
    ) -> int:
        """Publish at the recorded spacing divided by `rate`; `on_publish(msg, wall_ns)` after each."""
        if rate <= 0:
            raise InputError(f"rate must be > 0, got {rate}", field="rate")
        if not messages:
            return 0
        self.prepare(messages)
        keep_out_of_collector()  # the messages, and whatever the process built before playing
        t0_bag = messages[0].t_ns
        t0 = time.perf_counter()
        count = 0
        for m in messages:
            if stop is not None and stop.is_set():
                break
            due = t0 + (m.t_ns - t0_bag) / 1e9 / rate
            delay = due - time.perf_counter()
            if delay > 0:
                if stop is None:
                    time.sleep(delay)
                elif stop.wait(delay):  # a long pause in the bag still ends at once on a stop
                    break
            self.publishers[m.topic].publish(m.raw)
            count += 1
            if on_publish is not None:
                on_publish(m, time.time_ns())
        return count


class RawRecorder:
    """Records topics to a bag as they arrive (raw CDR bytes, publisher send time as log time)."""

    def __init__(self, node: Node, out: Path, qos: QoSProfile | int = 1000) -> None:
        self.node = node
        self.bag = BagWriter(out)
        self.qos = qos
        self.counts: dict[str, int] = {}
        self.closed = False
        self._lock = threading.Lock()

    def subscribe(self, topic: str, msgtype: str) -> None:
        cls = message_class(msgtype)
        self.counts[topic] = 0

        def on_message(raw: bytes, info: dict[str, int]) -> None:
            # log time = the publisher's send time: keeps the publication order across topics
            # (receive order across subscriptions depends on the executor)
            t_ns = info.get("source_timestamp") or time.time_ns()
            with self._lock:
                if self.closed:  # arrived while the recording stopped: not in the bag
                    return
                self.bag.write_raw(topic, msgtype, t_ns, raw)
                self.counts[topic] += 1

        # rclpy passes (msg, MessageInfo) to a two-argument callback; its annotation names only
        # the one-argument form
        self.node.create_subscription(cls, topic, on_message, self.qos, raw=True)  # type: ignore[arg-type]

    def resolve(
        self, topics: Sequence[str], timeout: float, stop: StopSignal | None = None
    ) -> dict[str, str]:
        """Type of each topic, from the ROS graph (waits up to `timeout` for them to appear)."""
        wanted = {t if t.startswith("/") else "/" + t for t in topics}
        found: dict[str, str] = {}

        def seen() -> bool:
            for name, types in self.node.get_topic_names_and_types():
                if name in wanted and types:
                    found[name] = types[0]
            return wanted <= set(found)

        wait_until(seen, timeout, poll=0.1, stop=stop)
        return found

    def close(self) -> None:
        """Finish the bag (readable from now on); later messages are not written."""
        with self._lock:
            if not self.closed:
                self.closed = True
                self.bag.close()

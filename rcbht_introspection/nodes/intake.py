"""The robot's intake of a node (segmenter_node, verifier_node): wrench per arm and /task_phase.

Both nodes take samples and events the same way: by an rclpy executor (callbacks with message
objects; the EventsExecutor by default) or drained in bursts (`spin: draining`,
nodes/draining.py: raw CDR decoded directly, and the events already delivered handled before
each sample).
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
from rclpy.subscription import Subscription
from std_msgs.msg import String

from rcbht_introspection.io.bags import decode_wrench_sample
from rcbht_introspection.nodes.conversions import wrench_sample
from rcbht_introspection.nodes.draining import DrainedGroup, take, take_bursts

OnSample = Callable[[str, int, Sequence[float], int | None], None]
"""(arm, stamp ns, six wrench values, DDS source timestamp ns or None)."""
OnPhase = Callable[[str, int | None], None]
"""(event name, DDS source timestamp ns or None)."""


_Item = tuple[int | None, str, str | tuple[int, Sequence[float]]]
"""(source timestamp, arm ('' for an event), event name or (stamp ns, wrench))."""


Subscribe = Callable[..., Subscription]
"""ManagedNode.subscribe: (type, topic, handler(msg, source ns or None), qos, **kwargs)."""


def _source(info: Any) -> int | None:
    """The DDS source timestamp of rclpy's MessageInfo (None when the middleware has none)."""
    return (info.get("source_timestamp") if info else None) or None


class Intake:
    """The wrench subscription of each arm and the /task_phase subscription, created at
    activate and destroyed at deactivate; samples and events go to `on_sample` / `on_phase`."""

    def __init__(
        self,
        node: Node,
        subscribe: Subscribe,
        topics: tuple[Sequence[str], Sequence[str], str],
        on_sample: OnSample,
        on_phase: OnPhase,
        qos: QoSProfile,
        draining: bool,
    ) -> None:
        arms, wrench_topics, phase_topic = topics
        self.node, self.on_sample, self.on_phase = node, on_sample, on_phase
        self.draining = draining
        self.burst: list[_Item] = []
        """The executor path: what the callbacks delivered since the last settled()."""
        # drained subscriptions are taken by drain(), not by executor callbacks
        group = DrainedGroup() if draining else None
        self.wrench: list[tuple[str, Subscription]] = [
            (
                arm,
                subscribe(
                    WrenchStamped, topic, partial(self._sample, arm), qos, raw=draining,
                    callback_group=group,
                ),
            )
            for arm, topic in zip(arms, wrench_topics, strict=True)
        ]  # fmt: skip
        self.phase = subscribe(String, phase_topic, self._phase, qos, callback_group=group)

    def _phase(self, msg: String, source: int | None) -> None:
        item: _Item = (source, "", msg.data)
        if self.draining:
            self._dispatch(item)
        else:
            self.burst.append(item)

    def _sample(self, arm: str, msg: bytes | WrenchStamped, source: int | None) -> None:
        if isinstance(msg, bytes):
            self.take_phases()  # an event published before this sample is handled before it
            try:
                stamp, wrench = decode_wrench_sample(msg)
            except (ValueError, struct.error):
                stamp, wrench = wrench_sample(deserialize_message(msg, WrenchStamped))
            self.on_sample(arm, stamp, wrench, source)
        else:
            self.burst.append((source, arm, wrench_sample(msg)))

    def _dispatch(self, item: _Item) -> None:
        source, arm, payload = item
        if isinstance(payload, str):
            self.on_phase(payload, source)
        else:
            self.on_sample(arm, payload[0], payload[1], source)

    def settled(self) -> None:
        """The executor path: the burst's events and samples, in publication order (DDS source
        timestamps; arrival order without them), so an event is handled before the samples
        published after it, as `take_phases` does when drained."""
        burst, self.burst = self.burst, []
        if all(source is not None for source, _, _ in burst):
            burst.sort(key=lambda item: item[0] or 0)  # stable: each topic keeps its order
        for item in burst:
            self._dispatch(item)

    def take_phases(self) -> None:
        """Drained: handle the /task_phase events already delivered (before the next sample)."""
        while (taken := take(self.phase)) is not None:
            self._phase(taken[0], _source(taken[1]))

    def drain(self) -> None:
        """Drained: every event and sample already delivered (arms in turn), in order.

        rclpy's per-wake-up cost dominates at 1 kHz; taking a burst at once keeps the node
        ahead of two 1 kHz arms. Bounded, so the node's timers still run.
        """
        self.take_phases()
        take_bursts(self.wrench, lambda arm, msg, info: self._sample(arm, msg, _source(info)))

    def publishers(self) -> int:
        """Fewest publishers matched on any intake topic. A harness waits for >= 1 before it
        plays: a writer can match this reader before this reader matches the writer, and DDS
        drops what it sends in between."""
        return min(sub.get_publisher_count() for sub in (*(s for _, s in self.wrench), self.phase))

    def destroy(self) -> None:
        """Unsubscribe (deactivate)."""
        for _, sub in self.wrench:
            self.node.destroy_subscription(sub)
        self.node.destroy_subscription(self.phase)
        self.wrench = []

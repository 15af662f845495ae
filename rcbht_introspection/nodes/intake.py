"""The robot's intake of a node (segmenter_node, verifier_node): wrench per arm and /task_phase.

Both nodes take samples and events the same way: each message goes to `live/order.Arrivals`
with its DDS source timestamp (None under the EventsExecutor), and at each `settled()` the
node's session gets them in publication order.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import partial

from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.subscription import Subscription
from std_msgs.msg import String

from rcbht_introspection.live.order import Arrivals
from rcbht_introspection.nodes.conversions import wrench_sample

OnSample = Callable[[str, int, Sequence[float], int | None], None]
"""(arm, stamp ns, six wrench values, DDS source timestamp ns or None)."""
OnPhase = Callable[[str, int | None], None]
"""(event name, DDS source timestamp ns or None)."""
Subscribe = Callable[..., Subscription]
"""ManagedNode.subscribe: (type, topic, handler(msg, source ns or None), qos)."""

_Item = tuple[str, str | tuple[int, Sequence[float]]]
"""(arm ('' for an event), event name or (stamp ns, wrench))."""


def fewest_publishers(subscriptions: Sequence[Subscription]) -> int:
    """Fewest publishers any of `subscriptions` matched (0 for none). A harness waits for >= 1
    before it plays: a writer can match a reader before the reader matches the writer, and what
    it sends in between arrives only with a retransmission."""
    return min((sub.get_publisher_count() for sub in subscriptions), default=0)


class Intake:
    """The wrench subscription of each arm and the /task_phase subscription, created at
    activate and destroyed at deactivate; samples and events go to `on_sample` / `on_phase`."""

    def __init__(
        self,
        node: Node,
        subscribe: Subscribe,
        topics: tuple[Sequence[str], Sequence[str], str],
        handlers: tuple[OnSample, OnPhase],
        qos: QoSProfile,
    ) -> None:
        arms, wrench_topics, phase_topic = topics
        self.node = node
        self.on_sample, self.on_phase = handlers
        self.arrivals: Arrivals[_Item] = Arrivals()
        self.wrench: list[tuple[str, Subscription]] = [
            (arm, subscribe(WrenchStamped, topic, partial(self._sample, arm), qos))
            for arm, topic in zip(arms, wrench_topics, strict=True)
        ]
        self.phase = subscribe(String, phase_topic, self._phase, qos)

    def _phase(self, msg: String, source: int | None) -> None:
        self.arrivals.add(source, ("", msg.data))

    def _sample(self, arm: str, msg: WrenchStamped, source: int | None) -> None:
        self.arrivals.add(source, (arm, wrench_sample(msg)))

    def settled(self) -> None:
        """The executor ran what was delivered: the events and samples, in publication order."""
        for source, (arm, payload) in self.arrivals.release():
            if isinstance(payload, str):
                self.on_phase(payload, source)
            else:
                self.on_sample(arm, payload[0], payload[1], source)

    def publishers(self) -> int:
        """Fewest publishers matched on any intake topic (fewest_publishers)."""
        return fewest_publishers([*(s for _, s in self.wrench), self.phase])

    def destroy(self) -> None:
        """Unsubscribe (deactivate)."""
        for _, sub in self.wrench:
            self.node.destroy_subscription(sub)
        self.node.destroy_subscription(self.phase)
        self.wrench = []

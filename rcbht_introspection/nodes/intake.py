"""The robot's intake of a node (segmenter_node, verifier_node): wrench per arm and /task_phase.

Both nodes take samples and events the same way: each message goes to `live/order.Arrivals`
with its DDS source timestamp (None under the EventsExecutor), and at each `settled()` (after
the executor's burst: nodes/common.spin) the node's session gets them in publication order.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from functools import partial

from geometry_msgs.msg import WrenchStamped
from rclpy.qos import QoSProfile
from rclpy.subscription import Subscription
from std_msgs.msg import String

from rcbht_introspection.configure.params import SegmenterConfig, VerifierConfig
from rcbht_introspection.live.order import Arrivals
from rcbht_introspection.messages import wrench_sample
from rcbht_introspection.nodes.common import ManagedNode

OnSample = Callable[[str, int, Sequence[float], int | None], None]
"""(arm, stamp ns, six wrench values, DDS source timestamp ns or None)."""
OnPhase = Callable[[str, int | None], None]
"""(event name, DDS source timestamp ns or None)."""
OnTick = Callable[[bool], None]
"""(no sample for the event hold time): a session's held events may be due."""

_Item = tuple[str, str | tuple[int, Sequence[float]]]
"""(arm ('' for an event), event name or (stamp ns, wrench))."""


def fewest_publishers(subscriptions: Sequence[Subscription]) -> int:
    """Fewest publishers any of `subscriptions` matched (0 for none). A harness waits for >= 1
    before it plays: a writer can match a reader before the reader matches the writer, and what
    it sends in between arrives only with a retransmission."""
    return min((sub.get_publisher_count() for sub in subscriptions), default=0)


class Intake:
    """The wrench subscription of each arm, the /task_phase subscription and the hold timer,
    created at activate (ManagedNode destroys them after deactivate): samples and events go to `on_sample` /
    `on_phase`, and every quarter of the event hold time (at most 50 ms) `on_tick` is told
    whether samples stopped for longer than the hold (events they would apply are due)."""

    def __init__(
        self,
        node: ManagedNode,
        cfg: SegmenterConfig | VerifierConfig,
        handlers: tuple[OnSample, OnPhase, OnTick],
        qos: QoSProfile,
    ) -> None:
        self.node, self.hold_s = node, cfg.event_hold_s
        self.on_sample, self.on_phase, self.on_tick = handlers
        self.arrivals: Arrivals[_Item] = Arrivals()
        self.wrench: list[tuple[str, Subscription]] = [
            (arm, node.subscribe(WrenchStamped, topic, partial(self._sample, arm), qos))
            for arm, topic in zip(cfg.arms, cfg.wrench_topics, strict=True)
        ]
        self.phase = node.subscribe(String, cfg.phase_topic, self._phase, qos)
        self.last_sample = time.monotonic()
        self.timer = node.create_timer(min(self.hold_s / 4, 0.05), self._tick)

    def _tick(self) -> None:
        self.on_tick(time.monotonic() - self.last_sample > self.hold_s)

    def _phase(self, msg: String, source: int | None) -> None:
        self.arrivals.add(source, ("", msg.data))

    def _sample(self, arm: str, msg: WrenchStamped, source: int | None) -> None:
        self.last_sample = time.monotonic()
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

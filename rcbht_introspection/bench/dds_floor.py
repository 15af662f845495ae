"""The DDS floor: WrenchStamped from one process to another at 1 kHz through rclpy, no processing.

What the middleware alone costs on this machine under the same load: the ROS benchmark runs it in
the same run as the nodes and reports their latencies as ratios to the floor's p99. Both ends use
rclpy's own serialisation and executor and the segmenter's wrench QoS (reliable, keep last 10000);
the publisher stamps each message with the wall clock just before publishing, the subscriber
subtracts it from the wall clock in its callback.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from rcbht_introspection.live.offline import percentiles_ms
from rcbht_introspection.replay.supervision import lease_domain, release_domain, ros_env

TOPIC = "/wrench"
QOS_DEPTH = 10000
QUIET_S = 5.0
"""The subscriber stops this long after the last message (or before the first)."""


def _node(name: str) -> Any:
    import rclpy
    from rclpy.node import Node

    rclpy.init()
    return Node(name)


def publish(rate_hz: float, count: int) -> int:
    """Publish `count` stamped wrenches at `rate_hz` once a subscriber has matched."""
    from geometry_msgs.msg import WrenchStamped

    from rcbht_introspection.nodes.common import qos_profile

    node = _node("dds_floor_publisher")
    pub = node.create_publisher(WrenchStamped, TOPIC, qos_profile(QOS_DEPTH, "reliable"))
    deadline = time.monotonic() + 30.0
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    msg, start = WrenchStamped(), time.monotonic()
    for i in range(count):
        delay = start + i / rate_hz - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        now = time.time_ns()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, 10**9)
        msg.wrench.force.z = float(i)
        pub.publish(msg)
    time.sleep(1.0)  # let reliable delivery finish before the participant goes
    node.destroy_node()
    return 0


def subscribe(count: int) -> int:
    """Receive up to `count` wrenches; print their publish -> callback latency as JSON."""
    import rclpy
    from geometry_msgs.msg import WrenchStamped

    from rcbht_introspection.nodes.common import qos_profile

    node = _node("dds_floor_subscriber")
    latencies: list[int] = []

    def on_wrench(msg: WrenchStamped) -> None:
        stamp = msg.header.stamp
        latencies.append(time.time_ns() - (stamp.sec * 10**9 + stamp.nanosec))

    node.create_subscription(WrenchStamped, TOPIC, on_wrench, qos_profile(QOS_DEPTH, "reliable"))
    last, seen = time.monotonic() + 30.0, 0
    while len(latencies) < count and time.monotonic() - last < QUIET_S:
        rclpy.spin_once(node, timeout_sec=0.1)
        if len(latencies) > seen:
            last, seen = time.monotonic(), len(latencies)
    print(json.dumps({"received": len(latencies), "latency_ms": percentiles_ms(latencies)}))
    node.destroy_node()
    return 0


def run_floor(rate_hz: float, seconds: float) -> dict[str, Any]:
    """Publisher and subscriber in processes of their own on a leased, loopback-only domain."""
    count = int(rate_hz * seconds)
    domain = lease_domain()
    try:
        with tempfile.TemporaryDirectory() as logs:
            env = {**os.environ, **ros_env(domain, Path(logs))}
            me = [sys.executable, "-m", "rcbht_introspection.bench.dds_floor"]
            sub = subprocess.Popen(
                [*me, "subscribe", str(count)], env=env, stdout=subprocess.PIPE, text=True
            )
            pub = subprocess.run([*me, "publish", str(count), "--rate", str(rate_hz)], env=env)
            out, _ = sub.communicate(timeout=seconds + 120)
    finally:
        release_domain(domain)
    received: dict[str, Any] = json.loads(out)
    return {
        "rate_hz": rate_hz,
        "published": count,
        "dropped": count - received["received"],
        "latency_ms": received["latency_ms"],
        "exit_codes": [pub.returncode, sub.returncode],
    }


def main(argv: list[str] | None = None) -> int:
    """`python -m rcbht_introspection.bench.dds_floor {publish,subscribe} COUNT [--rate HZ]`."""
    parser = argparse.ArgumentParser(prog="python -m rcbht_introspection.bench.dds_floor")
    parser.add_argument("role", choices=("publish", "subscribe"))
    parser.add_argument("count", type=int)
    parser.add_argument("--rate", type=float, default=1000.0)
    args = parser.parse_args(argv)
    if args.role == "publish":
        return publish(args.rate, args.count)
    return subscribe(args.count)


if __name__ == "__main__":
    sys.exit(main())

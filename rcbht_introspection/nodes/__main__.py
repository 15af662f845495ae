"""`python -m rcbht_introspection.nodes NODE [--ros-args ...]`: start one of the nodes.

The stop handlers go in before the node's modules are imported, so SIGINT/SIGTERM at any moment
of start-up end the process at once and cleanly (exit 0, no traceback); once the node is up, a
stop shuts it down in order.
"""

from __future__ import annotations

import sys

from rcbht_introspection.lifetime import StopSignal

NODES = ("segmenter_node", "classifier_node", "verifier_node", "sim_node", "planner_node")


def main(argv: list[str] | None = None) -> int:
    """Run the node named by the first argument; the rest are its (ROS) arguments."""
    argv = sys.argv[1:] if argv is None else argv
    stop = StopSignal.install(until_up=True)
    if not argv or argv[0] not in NODES:
        print(f"usage: python -m rcbht_introspection.nodes {{{','.join(NODES)}}} [--ros-args ...]")
        return 2
    name, args = argv[0], argv[1:]
    if name == "segmenter_node":
        from rcbht_introspection.nodes.segmenter_node import main as node_main
    elif name == "classifier_node":
        from rcbht_introspection.nodes.classifier_node import main as node_main
    elif name == "verifier_node":
        from rcbht_introspection.nodes.verifier_node import main as node_main
    elif name == "sim_node":
        from rcbht_introspection.nodes.sim_node import main as node_main
    else:
        from rcbht_introspection.nodes.planner_node import main as node_main
    return node_main(args, stop)


if __name__ == "__main__":
    sys.exit(main())

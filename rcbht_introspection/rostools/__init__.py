"""ROS tools around the nodes, for the CLI, the replay harness and the benches (not the nodes)."""

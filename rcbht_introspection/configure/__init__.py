"""What a node's configure does, without ROS: its typed parameters and the sessions they build."""

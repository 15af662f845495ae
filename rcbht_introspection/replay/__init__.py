"""The replay harness: the nodes as child processes over real DDS, fed bags, their output scored.

supervision.py runs the node processes (isolated ROS environment, wait, stop), observer.py
records their output (rclpy), scoring.py scores it (no ROS), harness.py is `rcbht replay-eval`.
"""

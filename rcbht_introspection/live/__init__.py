"""The live pipeline's state, pure Python: wrench samples -> stream words -> sub-task belief.

The ROS nodes are thin adapters over these classes (messages in, core calls, messages out), so
the same logic runs offline, in tests and in the benchmark without rclpy.
"""

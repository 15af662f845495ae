"""The live pipeline's state, pure Python: wrench samples -> stream words -> sub-task belief.

The ROS nodes are thin adapters over these classes (messages in, core calls, messages out), so
the same logic runs offline, in tests and in the benchmark without rclpy.
"""

from typing import Literal, get_args

BeliefMode = Literal["boundary", "window"]
"""boundary: the words since the last sub-task event; window: the last `window_s` seconds.
Here (not in belief.py) so the CLI lists the modes without importing the tracker."""
MODES: tuple[BeliefMode, ...] = get_args(BeliefMode)

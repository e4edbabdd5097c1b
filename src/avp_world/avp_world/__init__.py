"""ROS-free world model shared by the simulator, perception and planner.

Lot maps (paper §II-A), rectangle geometry, the discrete-time Reeds-Shepp car of eq. (1) and the
holonomic pedestrian of eq. (2). Nothing here imports rclpy or message classes.
"""

"""Rosbag2 without `ros2 bag`: recorder, damage-tolerant reader, MCAP storage, merge, replay, metrics from a bag."""

"""ROS-free core of the ego planner (paper §V-D): static world, Hybrid A*, control, decision logic."""

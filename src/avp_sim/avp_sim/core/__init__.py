"""ROS-free simulator core (paper §III, §VI-A): observation model, agents, scenarios, episodes."""

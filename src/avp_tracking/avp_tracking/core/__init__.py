"""The tracker's ROS-free core: motion model, association, track management (docs/perception.md, "Tracking")."""

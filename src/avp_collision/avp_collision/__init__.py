"""ROS-free collision checking shared by the ego planner and the Hybrid A* predictor (paper §V-D).

The static world (:mod:`.static`: the lot boundary, believed-occupied spots and parked cars, exactly as rectangles
and as an occupancy grid with its distance field; :mod:`.world_extend` builds one from another's grid), the
predicted agents as time-indexed obstacles (:mod:`.dynamic`, with :mod:`.reactive` for agents that brake for the
ego) and the settings they take (:mod:`.settings`). Nothing here imports rclpy.
"""

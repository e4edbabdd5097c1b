"""ROS-free search core shared by the ego planner and the Hybrid A* predictor (paper §V-D).

Hybrid A* over Reeds-Shepp shots (:mod:`.hybrid_astar`, :mod:`.rs_scalar`; the batched Reeds-Shepp lengths are
:mod:`avp_world.reeds_shepp`), collision checking against the lot and predicted agents (:mod:`.collision`), paths
as arcs (:mod:`.paths`) and the settings structs they take (:mod:`.settings`). Nothing here imports rclpy.
"""

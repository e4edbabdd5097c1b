"""ROS-free search core shared by the ego planner and the Hybrid A* predictor (paper §V-D).

Hybrid A* over Reeds-Shepp shots (:mod:`.hybrid_astar`, :mod:`.rs_scalar`; the batched Reeds-Shepp lengths are
:mod:`avp_world.reeds_shepp`), its heuristic (:mod:`.heuristic`), paths as arcs (:mod:`.paths`) and the settings
structs they take (:mod:`.settings`). Collision checking is avp_collision's. Nothing here imports rclpy.
"""

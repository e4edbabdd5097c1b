"""ROS-free motion layer under the planner's spot decision (paper §V-D, Alg. 1's plan and check).

:mod:`.settings` (the planner's settings struct), :mod:`.planner_search` and :mod:`.planner_candidates` (Hybrid A* to
a goal), :mod:`.planner_safety` (the plan against predicted agents), :mod:`.control` (path following),
:mod:`.waiting`, :mod:`.making_way` and :mod:`.yielding` (standing still, giving way), :mod:`.planner_inputs` (the
step's static world and agents), :mod:`.planner_types` and :mod:`.trace` (what the decision saw and did, for
`avp why`). Nothing here imports rclpy; avp_planner's decision and nodes sit on top.
"""

"""The lot as the ego believes it (paper §V-A, §V-B).

:mod:`.belief` (the occupancy belief of every spot, updated from what the ray-cast sensor sees), :mod:`.bev` (the
bird's-eye view drawn around an agent from the belief and the tracked agents, the intent CNN's input),
:mod:`.exploration` (where the ego looks next when no spot is free) and :mod:`.ego_trail` (the ego's own past poses).
Nothing here imports rclpy; avp_predictors and avp_perception sit on top.
"""

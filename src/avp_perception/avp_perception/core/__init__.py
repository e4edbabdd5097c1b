"""ROS-free perception core (paper §V-A..C): one perception step and the Nawaz et al. baseline.

Modules (never import rclpy or message classes here):

* :mod:`.pipeline` — one perception step: the belief map (avp_belief_map, eq. 7) -> the BEV -> the intent CNN
  (avp_predictors) -> eq. 8 -> the trajectory predictor (avp_predictors);
* :mod:`.nawaz` — the Nawaz et al. baseline: spot occupancy predicted from the predictions;
* :mod:`.debug_views` — the belief map as an occupancy grid and the BEVs tiled (the belief node's debug topics).
"""

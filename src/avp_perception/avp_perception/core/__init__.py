"""ROS-free perception core (paper §V-A..C): belief map, BEV reconstruction, intent CNN, trajectory prediction.

Modules (never import rclpy or message classes here):

* :mod:`.belief` — the belief map b_t and its two updates, eqs. (7) and (8) (§V-B);
* :mod:`.bev` — semantic BEV reconstruction of one observed dynamic vehicle, candidate spots and
  exploration points (§V-A, §V-B);
* :mod:`.intention` — the :class:`~.intention.Intention` record (eta_k,i and eta_hat_k,q, §V-A);
* :mod:`.intent_model` — the ParkPredict+ intent CNN and its feature computation (§V-A);
* :mod:`.prediction` — trajectory predictors (intention-conditioned cubic Bezier and constant velocity, §V-C);
* :mod:`.prediction_astar` — the Hybrid A* predictor (paths to the intended goals with the planner's search);
* :mod:`.debug_views` — the belief map as an occupancy grid and the BEVs tiled (the belief node's debug topics);
* :mod:`.pipeline` — one perception step chaining the above (eq. 7 -> BEV -> CNN -> eq. 8 -> prediction).
"""

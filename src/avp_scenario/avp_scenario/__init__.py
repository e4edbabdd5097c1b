"""ROS-free scenarios (paper §VI-A): an episode's parked cars, the other cars' plans and pedestrians
(:mod:`.scenario`), and ParkSim's 8 parking maneuvers the other cars drive (:mod:`.maneuvers`, with the scene they
are planned in, :mod:`.maneuver_scene`, and the tracking of their reference paths, :mod:`.maneuver_tracking`)."""

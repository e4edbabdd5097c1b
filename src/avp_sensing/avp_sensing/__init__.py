"""ROS-free sensing models: the ego's occlusion-aware ray-cast observation of paper §III-A (:mod:`.observation`,
:mod:`.ray_geometry`, :mod:`.occupancy`) and the noisy sensing model that replaces it outside ``sensing.model:
exact`` (:mod:`.noisy`: detections without ids, drifting localisation, misread spots)."""

"""The Table I experiment (paper §VI, issue #6), ROS-free except :mod:`.ros_transport`.

* :mod:`.profiles` — method profiles (``src/avp_bringup/config/methods/<name>.yaml``), planner settings;
* :mod:`.ego` — :class:`~.ego.MethodEgo`: one method's ego pipeline (perception cores + §V-D planner);
* :mod:`.metrics` — §VI-B metrics of an episode (minADE/minFDE from the ground truth) and their aggregates;
* :mod:`.runner` — ``avp experiment``: episodes in worker processes, resumable JSONL, summary;
* :mod:`.summary` — the Table I Markdown table (with the paper's numbers) and the PNG plots;
* :mod:`.paper` — Table I of the paper;
* :mod:`.ros_transport` — the same episodes through the live DDS graph (``--transport ros``).
"""

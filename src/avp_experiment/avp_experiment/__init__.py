"""The Table I experiment (paper §VI, docs/experiment.md), ROS-free except :mod:`.ros_collector`.

* :mod:`.profiles` — method profiles (``src/avp_experiment/config/methods/<name>.yaml``), planner settings;
* :mod:`.ego` — :class:`~.ego.MethodEgo`: one method's ego pipeline (perception cores + §V-D planner);
* :mod:`.metrics` — §VI-B metrics of an episode (minADE/minFDE from the ground truth) and their aggregates;
* :mod:`.runner` — ``avp experiment``: resumable JSONL, summary; :mod:`.episodes` — one episode, the workers;
* :mod:`.summary` — the Table I Markdown table (with the paper's numbers) and the PNG plots;
* :mod:`.paper` — Table I of the paper;
* :mod:`.transports` — ``--transport``: ``ros``, the live DDS graph, is avp_bringup's plugin
  (``avp_experiment_ros.transport``, with :mod:`.ros_collector`).
"""

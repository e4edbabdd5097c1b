"""The experiment (paper §VI, docs/experiment.md): the runner over seeds and methods, ROS-free.

* :mod:`.runner` — ``avp experiment``: valid seeds, episode keys, resumable records, the summary;
* :mod:`.arguments`, :mod:`.seeds` — its flags; which seeds build a scenario;
* :mod:`.results` — the records folder (identity, reading, writing, the lock);
* :mod:`.headline` — the suites behind the results tables; :mod:`.sweep`, :mod:`.failures` — sweeps, ablations,
  failed episodes replayed;
* :mod:`.ray_backend` — ``--backend ray``; :mod:`.transports` — ``--transport``: ``ros``, the live DDS graph, is the
  plugin ``avp_experiment_ros.transport``.

One episode in process (method profiles, protocols, the egos, metrics) is avp_episode's; the run's report beside the
paper's Table I is avp_report's.
"""

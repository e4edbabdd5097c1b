"""One experiment episode in process: what a method is and how it runs (paper §VI).

:mod:`.profiles` and :mod:`.protocols` (method profiles and protocols, ``config/methods/``, ``config/protocols/``),
:mod:`.run_config` (one run's settings), :mod:`.ego` (a method's perception, prediction and planner cores),
:mod:`.oracle` (the bound told the agents' plans), :mod:`.ego_pool` and :mod:`.fleet` (several egos),
:mod:`.sensing` (noisy sensing and the tracker between the simulator and the ego), :mod:`.inproc` (the chain
without a graph), :mod:`.episodes` (one episode and its record), :mod:`.metrics`, :mod:`.fleet_metrics`,
:mod:`.gridlock` (what a record says) and :mod:`.pool` (the worker processes). Nothing here imports rclpy;
avp_experiment runs these over seeds and methods.
"""

"""Where the episodes run (``avp experiment --transport``): ``inproc`` here, the others as plugins.

``inproc`` runs each episode on the simulator core in worker processes (:mod:`.runner`, :mod:`.episodes`). Any other
transport is a function registered in the entry-point group ``avp.experiment_transports``
(:mod:`avp_world.plugins`), called as ``run(keys, cfg, on_record, log_dir, timeout=seconds)`` to run the episode keys
``(method, seed, mode)`` and hand each record to ``on_record``. The live DDS graph's transport, ``ros``, is
avp_bringup's (``avp_experiment_ros.transport:run_ros``): it launches the node graph, which this package does not know.
"""

from __future__ import annotations

from collections.abc import Callable

from avp_world.plugins import available, load_class

GROUP = "avp.experiment_transports"
INPROC = "inproc"


def transport_names() -> list[str]:
    """``inproc`` and every transport installed as a plugin."""
    return [INPROC, *sorted(available(GROUP, {}))]


def load_transport(name: str) -> Callable:
    """The run function of plugin transport ``name``; ValueError naming the installed ones when it is unknown."""
    return load_class(GROUP, {}, name, "experiment transport", "docs/experiment.md")

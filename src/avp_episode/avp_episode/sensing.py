"""The noisy sensing model and the tracker in process (``sensing.model`` other than exact; docs/perception.md): the
simulator's :class:`~avp_sensing.noisy.NoisySensor` and avp_tracking's tracker between the world and the ego, as
the live graph has them between the simulator and the ego's nodes (avp_tracking.tracker_node)."""

from __future__ import annotations

from collections.abc import Callable

from avp_sensing.noisy import truth_ids
from avp_world.types import Observation

__all__ = ["relabel_predictions", "sensed_observer", "truth_ids"]


def sensed_observer(world, sim_p: dict, seed: int, tracker_values: dict | None = None, ego_index: int = 0
                    ) -> Callable[[], Observation] | None:
    """What ego ``ego_index`` of ``world`` observes each step through the sensing model and the tracker of the
    simulator parameters ``sim_p`` (tracker parameters: ``tracker_values``, default the shipped ones); None for
    ``sensing.model: exact`` (then ``world.observe`` is the observation, as in the paper)."""
    from avp_sensing.noisy import NoisySensor, sensing_config

    cfg = sensing_config(sim_p)
    if cfg.exact:
        return None
    if world.egos.count > 1:
        raise ValueError("sensing.model other than exact: one ego only (egos.count 1) for now")
    from avp_tracking.core.perceive import TrackingPerception
    from avp_tracking.core.tracker import Tracker
    from avp_tracking.params import default_tracker_values, tracker_config

    sensor = NoisySensor(cfg, seed, float(world.caster.region_range.max()), ego_index)
    tracker = Tracker(tracker_config(tracker_values or default_tracker_values(), world.dt, sim_p["t_hist"]))
    perception = TrackingPerception(world.lot, tracker)

    def observe() -> Observation:
        return perception.observe(sensor.sense(world, ego_index))

    observe.sensor, observe.tracker, observe.perception = sensor, tracker, perception  # for scoring and benches
    return observe


def relabel_predictions(preds: list, ids: dict[int, int]) -> list:
    """``preds`` with each track id replaced by the simulator id ``ids`` gives it (-1: no vehicle, not scored)."""
    from dataclasses import replace

    return [replace(p, agent_id=ids.get(int(p.agent_id), -1)) for p in preds]

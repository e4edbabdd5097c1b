"""The noisy sensing model and the tracker in process (``sensing.model`` other than exact; docs/perception.md): the
simulator's :class:`~avp_sim.core.sensing.NoisySensor` and avp_tracking's tracker between the world and the ego, as
the live graph has them between the simulator and the ego's nodes (avp_tracking.tracker_node)."""

from __future__ import annotations

from collections.abc import Callable

from avp_world.types import Observation


def sensed_observer(world, sim_p: dict, seed: int, tracker_values: dict | None = None, ego_index: int = 0
                    ) -> Callable[[], Observation] | None:
    """What ego ``ego_index`` of ``world`` observes each step through the sensing model and the tracker of the
    simulator parameters ``sim_p`` (tracker parameters: ``tracker_values``, default the shipped ones); None for
    ``sensing.model: exact`` (then ``world.observe`` is the observation, as in the paper)."""
    from avp_sim.core.sensing import NoisySensor, sensing_config

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


def truth_ids(world, obs: Observation, max_distance: float = 2.0) -> dict[int, int]:
    """For scoring only: the simulator id of the vehicle each of ``obs``'s tracks follows now (the nearest one by
    an optimal one-to-one pairing of their centres, within ``max_distance`` m); a track that follows no vehicle
    (clutter) is left out. The ego never sees this."""
    import numpy as np
    from scipy.optimize import linear_sum_assignment

    if not obs.vehicles or not len(world.states):
        return {}
    est = np.array([v.history[-1][:2] for v in obs.vehicles])
    d = np.hypot(est[:, None, 0] - world.states[None, :, 0], est[:, None, 1] - world.states[None, :, 1])
    rows, cols = linear_sum_assignment(np.where(d < max_distance, d, 1e9))
    return {int(obs.vehicles[r].id): int(world.vehicle_ids[c]) for r, c in zip(rows, cols, strict=True)
            if d[r, c] < max_distance}


def relabel_predictions(preds: list, ids: dict[int, int]) -> list:
    """``preds`` with each track id replaced by the simulator id ``ids`` gives it (-1: no vehicle, not scored)."""
    from dataclasses import replace

    return [replace(p, agent_id=ids.get(int(p.agent_id), -1)) for p in preds]

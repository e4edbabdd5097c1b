"""Run episodes in-process (no ROS): the same cores the nodes wrap, for tests and the experiment runner."""

from __future__ import annotations

from collections.abc import Callable

from avp_sim.core.world import World
from avp_world.types import Observation

Controller = Callable[[Observation], tuple[float, float]]


def run_episode(world: World, controller: Controller, max_steps: int | None = None) -> World:
    """Lock-step loop: observe, decide, step — until the episode ends (or ``max_steps``)."""
    n = 0
    while not world.done and (max_steps is None or n < max_steps):
        obs = world.observe()
        v, om = controller(obs)
        world.step(v, om)
        n += 1
    return world


def perception_planner(lot, belief_values: dict, prediction_values: dict, planner_settings):
    """The default live graph's ego side in one process (belief node -> prediction node -> planner), built from
    validated node parameter values as the nodes build theirs: a
    :class:`avp_episode.ego.MethodEgo` (the one in-process ego chain) and a controller for
    :func:`run_episode`; ``.last`` is its latest :class:`~avp_episode.ego.EgoStep`."""
    import torch

    from avp_episode.ego import MethodEgo
    from avp_perception.core.pipeline import PerceptionCore, make_intent_predictor
    from avp_perception.params import bev_config, prediction_config
    from avp_planner.core.decision import EgoPlanner
    from avp_predictors.prediction import make_predictor

    torch.set_num_threads(belief_values["torch_threads"])
    cfg = bev_config(belief_values)
    intent, _ = make_intent_predictor(lot, cfg, belief_values["intent.weights"], belief_values["intent.seed"],
                                      belief_values["intent.mode"])
    core = PerceptionCore(lot, cfg, intent=intent, t_hist=belief_values["t_hist"],
                          belief_init=belief_values["belief_init"])
    predictor = make_predictor(prediction_values["method"], lot, prediction_config(prediction_values))
    return MethodEgo.from_parts(lot, core, predictor, EgoPlanner(lot, planner_settings))

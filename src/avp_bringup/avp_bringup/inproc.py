"""Run episodes in-process (no ROS): the same cores the nodes wrap, for tests and the experiment runner."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

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


class PerceptionPlanner:
    """The ego side of the full graph in one process: belief node -> prediction node -> planner.

    Per observation: :meth:`PerceptionCore.perceive` (eq. 7, BEVs, intent CNN, eq. 8), the predictor on the
    intentions, :meth:`EgoPlanner.decide` on the beliefs and predictions. Between them the values are rounded
    as the messages round them (SpotBeliefs.beliefs, intention and trajectory probabilities are float32;
    everything else is float64), so an episode equals the graph's over DDS bit for bit
    (tests/test_dds_lockstep.py). ``last`` keeps the latest (beliefs, intentions, predictions, decision).

    Args:
        perception: the belief side (its own predictor is not used).
        predictor: the prediction node's predictor (``make_predictor(method, lot, config)``).
        planner: the ego planner (``EgoPlanner``).
    """

    def __init__(self, perception, predictor, planner):
        self.perception = perception
        self.predictor = predictor
        self.planner = planner
        self.last: tuple | None = None

    def __call__(self, obs: Observation) -> tuple[float, float]:
        from avp_perception.core.pipeline import float32_beliefs, float32_intention

        out = self.perception.perceive(obs)
        beliefs = float32_beliefs(out.beliefs)
        intentions = [float32_intention(it) for it in out.intentions]
        predictions = [replace(p, probability=float(np.float32(p.probability)))
                       for p in self.predictor.predict(obs, intentions)]
        decision = self.planner.decide(obs, beliefs, predictions)
        self.last = (beliefs, intentions, predictions, decision)
        return decision.command


def perception_planner(lot, belief_values: dict, prediction_values: dict, planner_settings) -> PerceptionPlanner:
    """A :class:`PerceptionPlanner` built from validated node parameter values (as the nodes build theirs)."""
    import torch

    from avp_perception.core.pipeline import PerceptionCore, make_intent_predictor
    from avp_perception.core.prediction import make_predictor
    from avp_perception.params import bev_config, prediction_config
    from avp_planner.core.decision import EgoPlanner

    torch.set_num_threads(belief_values["torch_threads"])
    cfg = bev_config(belief_values)
    intent, _ = make_intent_predictor(lot, cfg, belief_values["intent.weights"], belief_values["intent.seed"],
                                      belief_values["intent.mode"])
    core = PerceptionCore(lot, cfg, intent=intent, t_hist=belief_values["t_hist"],
                          belief_init=belief_values["belief_init"])
    predictor = make_predictor(prediction_values["method"], lot, prediction_config(prediction_values))
    return PerceptionPlanner(core, predictor, EgoPlanner(lot, planner_settings))

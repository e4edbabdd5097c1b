"""One method's ego pipeline (ROS-free): perception cores + the §V-D planner, one :meth:`MethodEgo.step` per
observation — the in-process twin of the live graph of a method (``avp_bringup.graph.method_graph``: the belief
node, the prediction node and the planner configured from the profile), used by ``avp experiment --transport
inproc``.

Per step, following the method profile (:mod:`.profiles`):

1. the belief node's step (:meth:`PerceptionCore.believe`): eq. (7), then per ``beliefs`` — ``intent``: the
   intent CNN of §V-A on every observed dynamic vehicle's reconstructed BEV (§V-B) and eq. (8); ``nawaz``:
   Nawaz et al.'s occupancy from constant-velocity predictions on the observed vacant spots
   (:mod:`avp_perception.core.nawaz`); ``observation``: nothing more — and with ``ego_intent`` the intent CNN
   on the ego's own BEV (:mod:`avp_predictors.implicit`);
2. the prediction node's step: the other agents' trajectories (§V-C) with the profile's predictor, conditioned
   on the intentions of step 1 (none for ``observation`` / ``nawaz``);
3. the planner's decision (:meth:`EgoPlanner.decide`; ``ego_intent``: candidate spots tried in decreasing
   eta_0,i).

``message_precision`` (default on) rounds what travels in float32 message fields between the nodes (intention
probabilities into the predictor and the planner's spot order, trajectory probabilities and b_t into the
planner) exactly as the messages do, so that in-process episodes equal the node graph's bit for bit
(tests/test_experiment.py, tests/test_dds_lockstep.py). It is the one in-process ego chain: the experiment builds it
from a method profile, the DDS tests from the nodes' parameter files (:meth:`MethodEgo.from_parts`).

Spot-selection time (Table I) = steps 1-2 + the planner's candidate selection and pricing; path-planning
time = the planner's Hybrid A* searches and tracking (§VI-B).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from avp_belief_map.bev import BEVConfig
from avp_episode.profiles import MethodProfile, planner_settings, prediction_config
from avp_perception.core.nawaz import NawazConfig, NawazOccupancy
from avp_perception.core.pipeline import PerceptionCore, float32_beliefs, float32_intention
from avp_planner.core.decision import Decision, EgoPlanner
from avp_predictors.implicit import spot_priority
from avp_world.lot import LotMap
from avp_world.types import Observation, PredictedTrajectory


@dataclass
class EgoStep:
    """What the ego did at one step."""

    step: int
    command: tuple[float, float]
    decision: Decision
    beliefs: np.ndarray | None  # b_t given to the planner (None: the planner's own, eq. 7)
    predictions: list[PredictedTrajectory]  # the other agents' predicted trajectories (§V-C)
    priority: np.ndarray | None = None  # implicit method: spot ids, most wanted first
    timings: dict = field(default_factory=dict)  # spot_selection_time, path_planning_time, perception_time [s]


class MethodEgo:
    """The ego of one Table I method; see the module docstring. One instance per episode (or :meth:`reset`).

    Args:
        lot: the lot map.
        profile: the method (:func:`~.profiles.load_profile`); must be ``available``.
        deterministic: lift the wall-clock caps of the planner and of the Hybrid A* predictor.
        intent_weights: intent CNN state-dict file; "" = the shipped weights if present, else seeded random; the
            profile's ``perception.intent_weights`` when it sets one.
        intent_seed: seed of the random weights.
        message_precision: round float32 message fields as the node graph does.
    """

    def __init__(self, lot: LotMap, profile: MethodProfile, *, deterministic: bool = True, intent_weights: str = "",
                 intent_seed: int = 0, message_precision: bool = True, bev_config: BEVConfig = BEVConfig(),
                 nawaz_config: NawazConfig = NawazConfig(), t_hist: float = 4.0):
        if not profile.available:
            raise ValueError(f"method {profile.name!r} is not available: {profile.unavailable_reason}")
        from avp_perception.core.pipeline import make_intent_predictor

        settings, use_beliefs, use_predictions = planner_settings(profile, deterministic)
        intent, self.intent_info = make_intent_predictor(lot, bev_config, profile.intent_weights or intent_weights,
                                                         intent_seed)
        core = PerceptionCore(lot, bev_config, predictor=profile.predictor,
                              prediction_config=prediction_config(deterministic, profile.prediction), intent=intent,
                              t_hist=t_hist)
        self._assemble(lot, profile, core, core.predictor, EgoPlanner(lot, settings), use_beliefs, use_predictions,
                       NawazOccupancy(lot, nawaz_config) if profile.beliefs == "nawaz" else None, message_precision)

    def _assemble(self, lot, profile, core, predictor, planner, use_beliefs, use_predictions, nawaz,
                  message_precision) -> None:
        self.lot, self.profile, self.core, self.predictor, self.planner = lot, profile, core, predictor, planner
        self.use_beliefs, self.use_predictions, self.nawaz = bool(use_beliefs), bool(use_predictions), nawaz
        self.message_precision = bool(message_precision)
        self.last: EgoStep | None = None

    @classmethod
    def from_parts(cls, lot: LotMap, core: PerceptionCore, predictor, planner: EgoPlanner, *,
                   name: str = "graph", message_precision: bool = True) -> MethodEgo:
        """The ego of the default live graph from cores built elsewhere (as the nodes build theirs from their
        parameter files: :func:`avp_episode.inproc.perception_planner`): intent beliefs, ``predictor`` (the
        prediction node's, not the core's), the planner using both."""
        ego = cls.__new__(cls)
        profile = MethodProfile(name=name, label=name, group="", available=True, beliefs="intent",
                                predictor=getattr(predictor, "name", "custom"), ego_intent=False, planner={})
        ego._assemble(lot, profile, core, predictor, planner, True, True, None, message_precision)
        ego.intent_info = ""
        return ego

    def __call__(self, obs: Observation) -> tuple[float, float]:
        """A controller for :func:`avp_episode.inproc.run_episode`: the command of :meth:`step`."""
        return self.step(obs).command

    def reset(self) -> None:
        self.core.reset()
        self.planner.reset()

    def predict(self, obs: Observation, b: np.ndarray, intentions: list) -> tuple[np.ndarray, list]:
        """The prediction node's step (§V-C): (b_t, predicted trajectories). A reference bound may replace it
        (``avp_episode.oracle.OracleEgo``)."""
        return b, self.predictor.predict(obs, intentions)

    def step(self, obs: Observation) -> EgoStep:
        prof = self.profile
        t0 = time.perf_counter()
        out = self.core.believe(obs, prof.beliefs, self.nawaz, prof.ego_intent)  # the belief node
        b, intentions, ego = out.beliefs, out.intentions, out.ego_intention
        if self.message_precision:
            intentions = [float32_intention(i) for i in intentions]
            ego = float32_intention(ego) if ego is not None else None
        t_belief = time.perf_counter() - t0
        b, predictions = self.predict(obs, b, intentions)
        if self.message_precision:
            predictions = [replace(p, probability=float(np.float32(p.probability))) for p in predictions]
            b = float32_beliefs(b)
        priority = spot_priority(ego) if ego is not None else None
        t_perception = time.perf_counter() - t0
        beliefs = b if self.use_beliefs else None
        preds = predictions if self.use_predictions else []
        dec = self.planner.decide(obs, beliefs, preds, priority)
        tm = dec.timings or {}
        timings = {"perception_time": t_perception, "belief_time": t_belief, "prediction_time": t_perception - t_belief,
                   "planner_time": float(tm.get("total", 0.0)),
                   "spot_selection_time": t_perception + float(tm.get("spot_selection_time", 0.0)),
                   "path_planning_time": float(tm.get("path_planning_time", 0.0))}
        self.last = EgoStep(int(obs.step), (float(dec.command[0]), float(dec.command[1])), dec, beliefs,
                            predictions, priority, timings)
        return self.last

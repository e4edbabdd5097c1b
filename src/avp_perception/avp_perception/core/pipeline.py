"""One perception step of the paper's pipeline (§V-A..C) on an :class:`Observation`.

    eq. (7)  b~_t = observation update of b_t-dt
    §V-B     BEV I_k,0 and I_k,i of every observed dynamic vehicle V_k from b~_t
    §V-A     intent CNN -> eta_k,i, eta_hat_k,q
    eq. (8)  b_t from b~_t and the intentions
    §V-C     predicted trajectories (Bezier conditioned on intentions >= mu, or constant velocity)

The ego's own recent poses are kept here (the observation carries only the current one) so that the
ego appears in the other vehicles' BEVs with a trail like every observed vehicle.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from avp_perception.core.belief import BELIEF_INIT, BeliefMap
from avp_perception.core.bev import BEVConfig, VehicleBEV
from avp_perception.core.intent_model import IntentPredictor
from avp_perception.core.intention import Intention
from avp_perception.core.prediction import PredictionConfig, make_predictor
from avp_world.lot import LotMap
from avp_world.types import Observation, PredictedTrajectory


@dataclass(frozen=True)
class PerceptionOutput:
    step: int
    b_tilde: np.ndarray  # (N_S,) after eq. (7)
    beliefs: np.ndarray  # (N_S,) b_t after eq. (8)
    intentions: list[Intention]
    trajectories: list[PredictedTrajectory]
    bevs: list[VehicleBEV] = field(default_factory=list)  # only with keep_bevs=True


class PerceptionCore:
    """Belief map + BEV + intent CNN + trajectory prediction, one :meth:`step` per observation."""

    def __init__(self, lot: LotMap, bev_config: BEVConfig = BEVConfig(), predictor: str = "bezier",
                 prediction_config: PredictionConfig = PredictionConfig(), intent: IntentPredictor | None = None,
                 seed: int = 0, t_hist: float = 4.0, belief_init: float = BELIEF_INIT, keep_bevs: bool = False):
        self.lot = lot
        self.beliefs = BeliefMap.from_lot(lot, belief_init)
        self.intent = intent if intent is not None else IntentPredictor(lot, bev_config, seed=seed)
        self.predictor = make_predictor(predictor, lot, prediction_config)
        self.t_hist = float(t_hist)
        self.keep_bevs = bool(keep_bevs)
        self._ego: deque[np.ndarray] = deque()
        self._last_step = -1

    def reset(self) -> None:
        self.beliefs.reset()
        self.intent.reset()
        self._ego.clear()
        self._last_step = -1

    def ego_history(self, obs: Observation) -> np.ndarray:
        """(H, 3) ego poses over the last t_hist, oldest first, ending with ``obs.ego_pose``."""
        if obs.step < self._last_step:  # time went back: a new episode
            self.reset()
        if obs.step == self._last_step and self._ego:  # the same observation again (re-sent)
            self._ego.pop()
        self._last_step = obs.step
        self._ego.append(np.asarray(obs.ego_pose, dtype=float).copy())
        keep = int(round(self.t_hist / obs.dt)) + 1 if obs.dt > 0 else 1
        while len(self._ego) > keep:
            self._ego.popleft()
        return np.array(self._ego)

    def step(self, obs: Observation) -> PerceptionOutput:
        ego_hist = self.ego_history(obs)
        b_tilde = self.beliefs.observe(obs.vacant_spot_ids, obs.occupied_spot_ids)  # eq. (7)
        dynamic = [v for v in obs.vehicles if not v.is_static]
        intentions, bevs = self.intent.predict_all(obs, dynamic, self.beliefs, ego_history=ego_hist,
                                                   return_bevs=True)  # §V-B, §V-A
        beliefs = self.beliefs.apply_intentions(intentions)  # eq. (8)
        trajectories = self.predictor.predict(obs, intentions)  # §V-C
        return PerceptionOutput(step=obs.step, b_tilde=b_tilde, beliefs=beliefs, intentions=intentions,
                                trajectories=trajectories, bevs=bevs if self.keep_bevs else [])

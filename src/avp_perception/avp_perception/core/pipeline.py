"""One perception step of the paper's pipeline (§V-A..C) on an :class:`Observation`.

    eq. (7)  b~_t = observation update of b_t-dt
    §V-B     BEV I_k,0 and I_k,i of every observed dynamic vehicle V_k from b~_t
    §V-A     intent CNN -> eta_k,i, eta_hat_k,q
    eq. (8)  b_t from b~_t and the intentions
    §V-C     predicted trajectories (Bezier conditioned on intentions >= mu, or constant velocity)

:meth:`PerceptionCore.believe` is the belief node's step for every method of Table I: after eq. (7) either
eq. (8) (``intent``, the paper), Nawaz et al.'s occupancy from constant-velocity predictions (``nawaz``,
§VI-B-2) or nothing (``observation``), and optionally the intent CNN on the ego's own BEV (§VI-B-3).

The ego's own recent poses are kept here (the observation carries only the current one) so that the
ego appears in the other vehicles' BEVs with a trail like every observed vehicle.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from avp_belief_map.belief import BELIEF_INIT, BELIEF_SOURCES, BeliefMap  # noqa: F401 - re-exported
from avp_belief_map.bev import BEVConfig, VehicleBEV
from avp_belief_map.ego_trail import EgoTrail
from avp_perception.core.nawaz import NawazOccupancy
from avp_predictors.implicit import ego_intention
from avp_predictors.intent_model import IntentPredictor, default_weights_path
from avp_predictors.intent_model import weights_path as intent_weights_path
from avp_predictors.intention import Intention
from avp_predictors.prediction import PredictionConfig, make_predictor
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




@dataclass(frozen=True)
class BeliefStep:
    """What the belief node publishes for one observation (:meth:`PerceptionCore.believe`)."""

    step: int
    beliefs: np.ndarray  # (N_S,) b_t
    intentions: list[Intention]  # the observed dynamic vehicles' (source "intent" only)
    ego_intention: Intention | None  # eta_0,i of the ego's own BEV (ego_intent only)
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
        self.keep_bevs = bool(keep_bevs)
        self.trail = EgoTrail(t_hist)

    def reset(self) -> None:
        self.beliefs.reset()
        self.intent.reset()
        self.trail.clear()

    def ego_history(self, obs: Observation) -> np.ndarray:
        """(H, 3) ego poses over the last t_hist, oldest first, ending with ``obs.ego_pose``."""
        if self.trail.went_back(obs):  # a new episode
            self.reset()
        return self.trail.update(obs)

    def perceive(self, obs: Observation) -> PerceptionOutput:
        """eq. (7) -> BEVs -> intent CNN -> eq. (8): what the belief node publishes (no trajectories)."""
        ego_hist = self.ego_history(obs)
        b_tilde = self.beliefs.observe(obs.vacant_spot_ids, obs.occupied_spot_ids)  # eq. (7)
        dynamic = [v for v in obs.vehicles if not v.is_static]
        intentions, bevs = self.intent.predict_all(obs, dynamic, self.beliefs, ego_history=ego_hist,
                                                   return_bevs=True)  # §V-B, §V-A
        beliefs = self.beliefs.apply_intentions(intentions)  # eq. (8)
        return PerceptionOutput(step=obs.step, b_tilde=b_tilde, beliefs=beliefs, intentions=intentions,
                                trajectories=[], bevs=bevs if self.keep_bevs else [])

    def believe(self, obs: Observation, source: str = "intent", nawaz: NawazOccupancy | None = None,
                ego_intent: bool = False) -> BeliefStep:
        """One belief-node step of any Table I method.

        ``source``: ``intent`` — :meth:`perceive` (eq. 7, BEVs, intent CNN, eq. 8); ``nawaz`` — eq. (7), then
        Nawaz et al.'s P_T on the observed vacant spots from constant-velocity predictions (``nawaz``, §VI-B-2);
        ``observation`` — eq. (7) only. ``ego_intent``: then the intent CNN on the ego's own BEV (§VI-B-3,
        :func:`~avp_predictors.implicit.ego_intention`).
        """
        if source not in BELIEF_SOURCES:
            raise ValueError(f"belief source must be one of {BELIEF_SOURCES}, got {source!r}")
        intentions: list[Intention] = []
        bevs: list[VehicleBEV] = []
        if source == "intent":
            out = self.perceive(obs)
            b, intentions, bevs = out.beliefs, out.intentions, out.bevs
            hist = self.ego_history(obs)  # the same observation again: the history is unchanged
        else:
            hist = self.ego_history(obs)
            b = self.beliefs.observe(obs.vacant_spot_ids, obs.occupied_spot_ids)  # eq. (7)
            if source == "nawaz":
                if nawaz is None:
                    raise ValueError("belief source 'nawaz' needs a NawazOccupancy")
                b = nawaz.update_constant_velocity(self.beliefs, obs)
        ego = ego_intention(self.intent, obs, self.beliefs, hist) if ego_intent else None
        return BeliefStep(step=obs.step, beliefs=np.asarray(b, dtype=float), intentions=intentions,
                          ego_intention=ego, bevs=bevs)

    def step(self, obs: Observation) -> PerceptionOutput:
        """:meth:`perceive`, then the predicted trajectories of §V-C."""
        out = self.perceive(obs)
        trajectories = self.predictor.predict(obs, out.intentions)  # §V-C
        return PerceptionOutput(step=out.step, b_tilde=out.b_tilde, beliefs=out.beliefs, intentions=out.intentions,
                                trajectories=trajectories, bevs=out.bevs)


# ------------------------------------------------------------------------------------ message precision


def float32_intention(it: Intention) -> Intention:
    """``it`` as it travels in avp_msgs/Intention: probabilities rounded to float32 (points stay float64)."""

    def f32(x) -> np.ndarray:
        return np.asarray(x, dtype=np.float32).astype(float)

    return replace(it, spot_probabilities=f32(it.spot_probabilities),
                   exploration_probabilities=f32(it.exploration_probabilities),
                   none_probability=float(np.float32(it.none_probability)))


def float32_beliefs(b: np.ndarray) -> np.ndarray:
    """b_t as it travels in avp_msgs/SpotBeliefs (float32)."""
    return np.asarray(b, dtype=np.float32).astype(float)


# ------------------------------------------------------------------------------------------ intent weights


def shipped_weights_path() -> Path | None:
    """The intent CNN weights shipped with the package (:func:`default_weights_path`), if present."""
    path = default_weights_path()
    return path if path.is_file() else None


def make_intent_predictor(lot: LotMap | None, bev_config: BEVConfig = BEVConfig(), weights: str = "", seed: int = 0,
                          mode: str = "incremental") -> tuple[IntentPredictor, str]:
    """The intent model of §V-A and a line saying which weights it runs with.

    ``weights``: a state-dict file (``torch.save(model.state_dict(), path)``) or the name of one in the package's
    models/ (e.g. ``intent_cnn_tracked.pt``); empty = the shipped weights (:func:`shipped_weights_path`) if present,
    else seeded random weights (valid but uninformative). A file that cannot be loaded raises ValueError naming it.
    """
    intent = IntentPredictor(lot, bev_config, seed=seed, mode=mode)
    path = intent_weights_path(weights) if weights else shipped_weights_path()
    if path is None:
        return intent, f"intent CNN: untrained seeded random weights (seed {seed}); no shipped weights found"
    try:
        intent.load_weights(path)
    except ValueError:  # load_cnn's own one-line error already names the file
        raise
    except Exception as exc:  # noqa: BLE001 - any unreadable file is one start-up error
        why = (str(exc).strip().splitlines() or [type(exc).__name__])[0]  # one line (torch's messages run long)
        raise ValueError(f"intent weights {path}: cannot load ({why})") from None
    return intent, f"intent CNN: weights from {path}" + ("" if weights else " (shipped)")

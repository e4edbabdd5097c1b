"""Implicit intent reasoning — the "Implicit" baseline of Table I (§VI-B-3), after ParkPredict+.

Shen et al., "ParkPredict+: Multimodal Intent and Motion Prediction for Vehicles in Parking Lots with CNN
and Transformer" (ITSC 2022) predict where a car intends to park from its semantic BEV. Chung et al.
implement an *implicit* AVP method with it by applying the intent model to **the ego only** (§VI-B-3):

    "At each timestep, we apply the intention prediction model on the ego, and constant velocity trajectory
    prediction on other agents. The ego would then prioritize spots with the highest intention probability
    that it can find a safe plan to."

So the ego is drawn as the target vehicle V_0 of its own reconstructed BEV (§V-B: the map, the observed
vehicles with their trails, default cars on unobserved spots believed occupied), the CNN of §V-A scores its
candidate spots, and the planner tries the observed vacant spots in decreasing eta_0,i until one has a safe
plan (:meth:`avp_planner.core.decision.EgoPlanner.decide` with ``spot_priority``). The other vehicles'
intentions are not predicted, so the belief map is eq. (7) alone.
"""

from __future__ import annotations

import numpy as np

from avp_belief_map.belief import BeliefMap
from avp_belief_map.bev import EGO_GROUP
from avp_predictors.intent_model import IntentPredictor
from avp_predictors.intention import Intention
from avp_world.types import Observation, ObservedVehicle, priority_from_probabilities

EGO_ID = EGO_GROUP  # the ego's id in the BEV scene (its trail group)


def ego_vehicle(obs: Observation, ego_history: np.ndarray) -> ObservedVehicle:
    """The ego as an observed dynamic vehicle: its size and its own recent poses (oldest first)."""
    h = np.asarray(ego_history, dtype=float).reshape(-1, 3)
    if len(h) == 0 or not np.array_equal(h[-1], np.asarray(obs.ego_pose, dtype=float)):
        raise ValueError("ego_history must end with the observation's ego pose")
    return ObservedVehicle(id=EGO_ID, length=float(obs.ego_length), width=float(obs.ego_width), is_static=False,
                           history=h)


def ego_intention(intent: IntentPredictor, obs: Observation, beliefs: BeliefMap,
                  ego_history: np.ndarray) -> Intention:
    """eta_0,i of the ego's candidate spots from its own BEV (§V-A/§V-B applied to V_0).

    ``beliefs`` must have seen this step's observation (:meth:`BeliefMap.observe`, eq. 7).
    """
    return intent.predict_all(obs, [ego_vehicle(obs, ego_history)], beliefs, ego_history=ego_history)[0]


def spot_priority(intention: Intention) -> np.ndarray:
    """Spot ids in decreasing intention probability (ties: smaller spot id first); the planner node orders the
    ``ego_intention`` message with the same function."""
    return priority_from_probabilities(intention.spot_ids, intention.spot_probabilities)

"""Parameters of the belief and prediction nodes (config/belief.param.yaml, config/prediction.param.yaml).

ROS-free. The core settings dataclasses (:class:`~avp_belief_map.bev.BEVConfig`,
:class:`~avp_predictors.prediction.PredictionConfig`) are the single source of the defaults and
descriptions (``specs_from_dataclass``); this module adds the node-only rows, the paper's symbols and
sections, and ranges. ``python tools/gen_params.py`` writes the YAML files and the tables of docs/parameters.md.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from avp_belief_map.belief import BELIEF_INIT, BELIEF_SOURCES
from avp_belief_map.bev import EXPLORATION_SHAPES, BEVConfig
from avp_common.params import ParamSpec, dataclass_from_values, specs_from_dataclass
from avp_perception.core.nawaz import COVARIANCE_MODES, MAHALANOBIS_MODES, NawazConfig
from avp_predictors.intent_features import INTENT_MODES
from avp_predictors.prediction import START_TANGENTS, PredictionConfig, available_predictors

DEBUG_CHOICES = ("never", "subscribed", "always")


def _annotate(specs: list[ParamSpec], notes: dict[str, dict[str, Any]]) -> list[ParamSpec]:
    unknown = set(notes) - {s.name for s in specs}
    if unknown:
        raise KeyError(f"annotations for unknown parameters {sorted(unknown)}")
    return [replace(s, **notes.get(s.name, {})) for s in specs]


BELIEF_NODE_PARAMS = [
    ParamSpec("auth_inputs", bool, "Take lot_map and observation only when tagged with the user's key "
              "(avp_common.msg_auth); others are dropped and their publishers named. Outputs are always tagged.",
              default=True),
    ParamSpec("belief_source", str, "What follows eq. (7): intent = eq. (8) with the intent CNN of every observed "
              "dynamic vehicle (the paper; intentions published); nawaz = Nawaz et al.'s occupancy P_T on the observed "
              "vacant spots from constant-velocity predictions computed in this node (nawaz.*; Table I 'Explicit, "
              "future'); observation = eq. (7) only. With nawaz/observation the intentions topic carries an empty "
              "array.", "b_t", "§V-B, §VI-B-2", choices=BELIEF_SOURCES, default="intent"),
    ParamSpec("ego_intent", bool, "Also run the intent CNN on the ego's own BEV and publish its intention on "
              "ego_intention (Table I 'Implicit (ParkPredict+)': the planner's use_ego_intention tries spots in "
              "decreasing eta_0,i).", "eta_0,i", "§VI-B-3", default=False),
    ParamSpec("belief_init", float, "Belief of a spot before any observation (no information).", "b_-dt", "§V-B",
              min=0.0, max=1.0, default=BELIEF_INIT),
    ParamSpec("t_hist", float, "Ego poses kept for the ego's trail in the other vehicles' BEVs (as the "
              "observed histories).", "t_hist", "§III-A", min=0.0, max=20.0, default=4.0),
    ParamSpec("intent.weights", str, "Intent CNN state-dict file, or the name of one in avp_predictors/models/ "
              "(e.g. intent_cnn_tracked.pt); empty = the shipped weights (avp_predictors/models/intent_cnn.pt) if "
              "present, else untrained seeded random weights. The node logs which.", "", "§V-A", default=""),
    ParamSpec("intent.seed", int, "Seed of the random weights (used only without a weights file).", "", "§V-A",
              min=0, max=2**31 - 1, default=0),
    ParamSpec("intent.mode", str, "Inference path (all compute the same logits; incremental is fastest).", "",
              "§V-A", choices=INTENT_MODES, default="incremental"),
    ParamSpec("torch_threads", int, "torch.set_num_threads for the CNN (1: deterministic and fastest on a "
              "shared CPU, bench/bench_perception.py).", min=1, max=64, default=1),
    ParamSpec("debug.bev", str, "Publish debug/bev (sensor_msgs/Image, the BEVs I_k,0 tiled): never, only while "
              "someone subscribes, or always.", "I_k,0", "§V-B", choices=DEBUG_CHOICES, default="subscribed"),
    ParamSpec("debug.occupancy", str, "Publish debug/occupancy (nav_msgs/OccupancyGrid of b_t): never, only while "
              "someone subscribes, or always.", "b_t", "§V-B", choices=DEBUG_CHOICES, default="subscribed"),
    ParamSpec("debug.occupancy_resolution", float, "Cell size of debug/occupancy.", min=0.05, max=5.0,
              default=0.25),
]

_BEV_NOTES: dict[str, dict[str, Any]] = {
    "bev.size_px": {"min": 8, "max": 1000, "section": "§V-B"},
    "bev.m_per_px": {"min": 0.01, "max": 2.0, "section": "§V-B"},
    "bev.beta": {"symbol": "β", "section": "§VI-A", "min": 0.0, "max": 1.0},
    "bev.default_length": {"symbol": "l_def", "section": "§VI-A", "min": 0.1},
    "bev.default_width": {"symbol": "w_def", "section": "§VI-A", "min": 0.1},
    "bev.spot_margin": {"section": "§V-B", "min": 0.0},
    "bev.spot_clear_halfwidth": {"section": "§V-B", "min": 0.0},
    "bev.target_blocks_spot": {"section": "§V-B"},
    "bev.trail_steps": {"section": "§V-B", "min": 0, "max": 100},
    "bev.trail_period": {"section": "§V-B", "min": 0.01},
    "bev.exploration_shape": {"symbol": "s_exp", "section": "§V-A", "choices": EXPLORATION_SHAPES},
    "bev.exploration_radius": {"symbol": "Q_0", "section": "§V-D, §VI-A", "min": 0.1},
}
_NAWAZ_NOTES: dict[str, dict[str, Any]] = {
    "nawaz.step": {"symbol": "h", "section": "§VI-B-2", "min": 0.01, "max": 10.0},
    "nawaz.n_steps": {"symbol": "T", "section": "§VI-B-2", "min": 0, "max": 100},
    "nawaz.sigma0_scale": {"symbol": "Σ_0", "section": "§VI-B-2", "min": 1e-6},
    "nawaz.q": {"symbol": "Q", "section": "§VI-B-2", "min": 0.0},
    "nawaz.pedestrian_sigma0_scale": {"section": "§VI-B-2", "min": 0.0},
    "nawaz.pedestrian_q_scale": {"section": "§VI-B-2", "min": 0.0},
    "nawaz.alpha_g": {"symbol": "α_g", "section": "§VI-B-2", "min": 1e-6},
    "nawaz.alpha": {"symbol": "α", "section": "§VI-B-2", "min": 0.0, "max": 1.0},
    "nawaz.rho": {"symbol": "ρ", "section": "§VI-B-2", "min": 0.0},
    "nawaz.gate_gain": {"symbol": "g", "section": "§VI-B-2", "min": 0.0},
    "nawaz.floor": {"section": "§VI-B-2", "min": 0.0, "max": 1.0},
    "nawaz.mahalanobis": {"section": "§VI-B-2", "choices": MAHALANOBIS_MODES},
    "nawaz.covariance": {"section": "§VI-B-2", "choices": COVARIANCE_MODES},
}
BELIEF_PARAMS: list[ParamSpec] = (BELIEF_NODE_PARAMS + _annotate(specs_from_dataclass(BEVConfig(), "bev."), _BEV_NOTES)
                                  + _annotate(specs_from_dataclass(NawazConfig(), "nawaz."), _NAWAZ_NOTES))

PREDICTION_NODE_PARAMS = [
    ParamSpec("auth_inputs", bool, "Take lot_map and observation (and intentions) only when tagged with the user's key "
              "(avp_common.msg_auth); others are dropped and their publishers named. Outputs are always tagged.",
              default=True),
    ParamSpec("method", str, "Trajectory predictor: the paper's intention-conditioned Bezier curves, constant "
              "velocity, Hybrid A* paths to the intended goals, or the learned transformer (learned.*, §VI-B-1).",
              "", "§V-C", choices=tuple(available_predictors()), default="bezier"),
]
_PRED_NOTES: dict[str, dict[str, Any]] = {
    "zeta": {"symbol": "ζ", "section": "eqs. (11)-(12), §VI-A", "min": 0.0, "max": 100.0},
    "mu": {"symbol": "μ", "section": "§V-C, §VI-A", "min": 0.0, "max": 1.0},
    "t_pred": {"symbol": "t_pred", "section": "§V-C", "min": 0.0, "max": 60.0},
    "start_tangent": {"section": "eq. (11)", "choices": START_TANGENTS},
    "samples": {"min": 4, "max": 100000},
    "hybrid_astar.max_iterations": {"section": "§V-D", "min": 1, "max": 1000000},
    "hybrid_astar.time_cap": {"min": 0.001, "max": 60.0},
    "hybrid_astar.max_length": {"min": 0.1},
    "hybrid_astar.min_speed": {"symbol": "v_hat", "section": "§V-C", "min": 0.0, "max": 10.0},
    "hybrid_astar.footprint_margin": {"min": 0.0, "max": 2.0},
    "learned.weights": {"section": "§VI-B-1"},
    "learned.seed": {"section": "§VI-B-1", "min": 0, "max": 2**31 - 1},
    "learned.threads": {"min": 1, "max": 64},
    "learned.t_hist": {"symbol": "t_hist", "section": "§III-A", "min": 0.0, "max": 20.0},
}
PREDICTION_PARAMS: list[ParamSpec] = PREDICTION_NODE_PARAMS + _annotate(specs_from_dataclass(PredictionConfig()),
                                                                      _PRED_NOTES)


def bev_config(values: dict[str, Any]) -> BEVConfig:
    """BEVConfig from validated ``bev.*`` values (ValueError from its own checks)."""
    return dataclass_from_values(BEVConfig(), values, "bev.").validate()


def nawaz_config(values: dict[str, Any]) -> NawazConfig:
    """NawazConfig from validated ``nawaz.*`` values (ValueError from its own checks)."""
    return dataclass_from_values(NawazConfig(), values, "nawaz.").validate()


def prediction_config(values: dict[str, Any]) -> PredictionConfig:
    """PredictionConfig from validated values (ValueError from its own checks)."""
    return dataclass_from_values(PredictionConfig(), values).validate()

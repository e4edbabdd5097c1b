"""What an experiment's episodes depend on besides (method, seed, mode), shared by the in-process runner and the
DDS transport (:mod:`.runner`, :mod:`.ros_transport`; a module of its own so that neither imports the other)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from avp_episode.profiles import MethodProfile, load_profile
from avp_episode.protocols import apply_planner, load_protocol

DEFAULT_HORIZON = 4.0  # s: t_pred of the predictors (ParkPredict+'s horizon; the paper does not state one)


@dataclass(frozen=True)
class RunConfig:
    """What the episodes' results depend on besides (method, seed, mode)."""

    t_final: float = 100.0  # t_f [s] (§VI-A)
    ade_horizon: float = DEFAULT_HORIZON  # H of minADE / minFDE [s]
    intent_weights: str = ""  # "" = shipped weights if present, else random (intent_seed)
    intent_seed: int = 0
    message_precision: bool = True
    sim_overrides: dict = field(default_factory=dict)  # further avp_sim parameters
    protocol: str = "default"  # config/protocols/<name>.yaml (.protocols): shared sim + planner set-up
    planner_overrides: dict = field(default_factory=dict)  # --planner-param: avp_planner values for every method
    tracker_overrides: dict = field(default_factory=dict)  # --tracker-param: avp_tracking values (noisy sensing)


Key = tuple[str, int, str]  # (method, seed, "reactive" | "non_reactive")
ORACLE_HORIZON = 10.0  # s of true future given to the oracle bound (.oracle; one ego or a fleet's, .fleet)


def sim_values(cfg: RunConfig) -> dict[str, Any]:
    """avp_sim parameters of the episodes: the shipped sim.param.yaml with t_f and the overrides."""
    from avp_common.params import load_yaml_params, validate_values
    from avp_common.share import package_share
    from avp_sim.params import SIM_PARAMS

    p = load_yaml_params(package_share("avp_sim") / "config" / "sim.param.yaml", "avp_sim", SIM_PARAMS)
    p.update(load_protocol(cfg.protocol).sim)
    p.update(cfg.sim_overrides)
    p["t_final"] = float(cfg.t_final)
    return validate_values(p, SIM_PARAMS, "avp experiment")


def tracker_values(cfg: RunConfig) -> dict[str, Any]:
    """avp_tracking parameters of the episodes' tracker (noisy sensing only): the shipped tracker.param.yaml's
    values with ``--tracker-param``'s over them."""
    from avp_common.params import validate_values
    from avp_tracking.params import TRACKER_PARAMS, default_tracker_values

    return validate_values({**default_tracker_values(), **cfg.tracker_overrides}, TRACKER_PARAMS, "--tracker-param")


def tracker_specs() -> dict:
    """The tracker's parameter specs by name (avp_tracking's, without its node's own)."""
    from avp_tracking.params import TRACKER_PARAMS

    return {s.name: s for s in TRACKER_PARAMS}


def run_profile(name: str, cfg: RunConfig) -> MethodProfile:
    """The method profile as the run uses it: the protocol's planner parameters, then ``--planner-param``, under
    the profile's own block (:func:`.protocols.apply_planner`)."""
    return apply_planner(load_profile(name), load_protocol(cfg.protocol).planner, cfg.planner_overrides)

"""Build worlds from the (validated) simulator parameters — shared by the node and in-process runners."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from avp_scenario.scenario import ScenarioParams, generate_paper_scenario
from avp_sensing.observation import SensorConfig
from avp_sim.core.scenario_cache import cached_scenario
from avp_sim.core.scenario_file import load_scenario_file, scenario_from_dict
from avp_sim.core.world import World, WorldConfig
from avp_traffic.busy import BusyParams, generate_busy_scenario
from avp_world.lot import LotMap, load_bundled_lot, load_lot


def load_lot_param(lot_file: str) -> LotMap:
    return load_lot(lot_file) if lot_file else load_bundled_lot("paper_lot")


def sensor_config(p: dict[str, Any]) -> SensorConfig:
    cfg = SensorConfig(
        n_ray=p["sensor.n_ray"], shape=p["sensor.shape"], radius=p["sensor.radius"], length=p["sensor.length"],
        width=p["sensor.width"], semi_major=p["sensor.semi_major"], semi_minor=p["sensor.semi_minor"],
        offset=tuple(p["sensor.offset"]),
    )
    cfg.validate()
    return cfg


def scenario_params(p: dict[str, Any]) -> ScenarioParams:
    if p["scenario.passiveness_min"] > p["scenario.passiveness_max"]:
        raise ValueError("parameter 'scenario.passiveness_min' must be <= 'scenario.passiveness_max'")
    if p["scenario.n_dynamic_min"] > p["scenario.n_dynamic_max"]:
        raise ValueError("parameter 'scenario.n_dynamic_min' must be <= 'scenario.n_dynamic_max'")
    if p["scenario.outer_row_min"] > p["scenario.outer_row_max"]:
        raise ValueError("parameter 'scenario.outer_row_min' must be <= 'scenario.outer_row_max'")
    for lo, hi in (("approach_distance_min", "approach_distance_max"), ("cruise_speed_min", "cruise_speed_max")):
        if p[f"scenario.{lo}"] > p[f"scenario.{hi}"]:
            raise ValueError(f"parameter 'scenario.{lo}' must be <= 'scenario.{hi}'")
    return replace(
        ScenarioParams(),
        dt=p["dt"], t_hist=p["t_hist"], t_final=p["t_final"],
        passiveness=(p["scenario.passiveness_min"], p["scenario.passiveness_max"]),
        n_dynamic=(p["scenario.n_dynamic_min"], p["scenario.n_dynamic_max"]),
        fallback_rows=(p["scenario.outer_row_min"], p["scenario.outer_row_max"]),
        maneuver_max_speed=p["scenario.maneuver_max_speed"],
        passiveness_step=p["scenario.passiveness_step"],
        approach_distance=(p["scenario.approach_distance_min"], p["scenario.approach_distance_max"]),
        cruise_speed=(p["scenario.cruise_speed_min"], p["scenario.cruise_speed_max"]),
        spawn_closer_than_ego=p["scenario.spawn_closer_than_ego"],
    )


def world_config(p: dict[str, Any], lot: LotMap | None = None) -> WorldConfig:
    """The world's settings of the simulator parameters ``p`` (driven cars' poses checked against ``lot``)."""
    return WorldConfig(t_final=p["t_final"], sensor=sensor_config(p), ego_max_speed=p["ego_max_speed"],
                       agents_yield=p["agents_yield"], n_egos=p["egos.count"],
                       entry_interval=p["egos.entry_interval"], entry_clearance=p["egos.entry_clearance"],
                       n_drivers=p["drivers.count"],
                       driver_enter_at=p["drivers.enter_at"], driver_poses=driver_poses(lot, p))


def make_world(lot: LotMap, p: dict[str, Any], seed: int, reactive: bool, scenario_file: str = "",
               scenario_data: tuple[str, Any] | None = None) -> World:
    """A fresh episode of the §VI-A protocol for ``seed`` (same seed ⇒ same episode), the scenario of
    ``scenario_file`` (a trusted local YAML file, :func:`avp_sim.core.scenario_file.load_scenario_file`) or of
    ``scenario_data`` ((source name, parsed YAML) of a request, :mod:`avp_sim.core.scenario_source`)."""
    if scenario_data is not None:
        scenario = scenario_from_dict(lot, scenario_data[1], scenario_data[0], seed, reactive, scenario_params(p))
    elif scenario_file:
        scenario = load_scenario_file(lot, scenario_file, seed, reactive, scenario_params(p))
    else:
        scenario = generate_scenario(lot, p, seed, reactive)
    return World(lot, scenario, world_config(p, lot))


def busy_params(p: dict[str, Any]) -> BusyParams:
    for lo, hi in (("occupancy_min", "occupancy_max"), ("arrival_gap_min", "arrival_gap_max"),
                   ("departure_gap_min", "departure_gap_max"), ("n_pedestrians_min", "n_pedestrians_max")):
        if p[f"busy.{lo}"] > p[f"busy.{hi}"]:
            raise ValueError(f"parameter 'busy.{lo}' must be <= 'busy.{hi}'")
    return BusyParams(occupancy=(p["busy.occupancy_min"], p["busy.occupancy_max"]),
                      arrival_gap=(p["busy.arrival_gap_min"], p["busy.arrival_gap_max"]),
                      departure_gap=(p["busy.departure_gap_min"], p["busy.departure_gap_max"]),
                      n_pedestrians=(p["busy.n_pedestrians_min"], p["busy.n_pedestrians_max"]))


def generate_scenario(lot: LotMap, p: dict[str, Any], seed: int, reactive: bool):
    """The seeded scenario of the family ``scenario.family`` (ScenarioError when the seed has none)."""
    if p.get("scenario.family", "paper") == "busy":  # kept on disk: about 9 s of CPU a seed
        busy = busy_params(p)
        return cached_scenario(lot, ("busy", seed, reactive, p["dt"], p["t_hist"], p["t_final"], busy),
                               lambda: generate_busy_scenario(lot, seed, reactive, dt=p["dt"], t_hist=p["t_hist"],
                                                              t_final=p["t_final"], busy=busy))
    return generate_paper_scenario(lot, seed, reactive, scenario_params(p))


def driver_poses(lot, p: dict) -> tuple:
    """``drivers.poses`` ('x,y,theta;x,y,theta', '' = the gate) as ((x, y, theta), ...); ValueError naming the
    parameter for a malformed value, more poses than driven cars, or a pose whose car lies outside the lot."""
    import math

    import numpy as np

    from avp_world.geometry import polygon_contains_points, rect_corners
    from avp_world.vehicle import DEFAULT_VEHICLE

    text = str(p.get("drivers.poses", "")).strip()
    poses = []
    for part in (text.split(";") if text else []):
        try:
            pose = tuple(float(v) for v in part.split(","))
        except ValueError:
            pose = ()
        if len(pose) != 3 or not all(math.isfinite(v) for v in pose):
            raise ValueError(f"parameter 'drivers.poses': {part!r}: expected 'x,y,theta' (finite numbers)")
        poses.append(pose)
    if len(poses) > int(p["drivers.count"]):
        raise ValueError(f"parameter 'drivers.poses': {len(poses)} poses for {p['drivers.count']} driven cars")
    car = DEFAULT_VEHICLE  # a driven car has the ego's body (avp_sim.core.egos)
    for j, pose in enumerate(poses if lot is not None else ()):
        if not polygon_contains_points(lot.boundary, rect_corners(np.asarray(pose), car.length, car.width)).all():
            raise ValueError(f"parameter 'drivers.poses': driven car {j} at {list(pose)} lies outside the lot")
    return tuple(poses)

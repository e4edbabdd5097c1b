"""Hand-written scenarios (a YAML file, or the text of a ``reset_episode`` request): validation and building.

:func:`scenario_from_dict` checks the counts first (vehicles, vacant spot ids: bounded work per request, even
a hostile one), then every field, naming the source and the field at fault, and builds the scenario with the
building blocks of :mod:`avp_scenario.scenario` (the same vehicles, plans and validity rule as §VI-A's protocol).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from avp_scenario.maneuvers import ALL_MANEUVERS
from avp_scenario.scenario import (
    Scenario,
    ScenarioError,
    ScenarioParams,
    VehicleAgent,
    _valid_dynamic,
    build_dynamic_vehicle,
)
from avp_world.geometry import polygon_contains_points, rect_corners
from avp_world.lot import LotMap
from avp_world.vehicle import VehicleSpec

MAX_DYNAMIC_VEHICLES = 64  # a scenario file's dynamic vehicles (bounded work per request)
MAX_EGOS = 8  # egos of one lot (avp_sim.core.egos): ego_start's and those of ``egos``

#: keys of a scenario file and of each dynamic_vehicles entry
_FILE_KEYS = {"seed", "reactive", "ego_start", "egos", "vacant_spot_ids", "dynamic_vehicles"}
_EGO_KEYS = {"start", "enter_at"}
_DYN_KEYS = {"target_spot", "maneuver", "cruise_speed", "approach_distance", "passiveness"}


def _number(v, where: str, lo: float = -math.inf, hi: float = math.inf) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ScenarioError(f"{where}: expected a finite number, got {v!r}")
    if not lo <= v <= hi:
        raise ScenarioError(f"{where}: {v} is outside [{lo}, {hi}]")
    return float(v)


def _integer(v, where: str, lo: int = 0, hi: int = 2**32 - 1) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise ScenarioError(f"{where}: expected an integer, got {v!r}")
    if not lo <= v <= hi:
        raise ScenarioError(f"{where}: {v} is outside [{lo}, {hi}]")
    return int(v)


def scenario_from_dict(lot: LotMap, data: dict, source: str, seed: int, reactive: bool,
                       params: ScenarioParams = ScenarioParams(), vehicle: VehicleSpec = VehicleSpec()) -> Scenario:
    """A hand-written scenario (the same ingredients as §VI-A, fixed instead of drawn).

    ``vacant_spot_ids``: the spots left empty (every other spot holds a parked car, heading flipped at
    random by ``seed``); ``dynamic_vehicles``: each parks in one of the vacant spots with one of ParkSim's 8
    maneuvers ("side/stop/entry", e.g. ``near/before/head_in``), cruising at ``cruise_speed`` and
    ``approach_distance`` from its maneuver start at t = 0, with passiveness n_pass (§III-B; 0 when not
    reactive); ``ego_start`` [x, y, theta]; ``egos``: further automated cars, each ``{start: [x, y, theta],
    enter_at: s}`` (avp_sim.core.egos). ``seed`` / ``reactive`` default to the request's. Every problem
    raises :class:`ScenarioError` naming ``source`` and the field.
    """
    params = params.resolve(lot)
    if not isinstance(data, dict):
        raise ScenarioError(f"{source}: top level must be a mapping with keys {sorted(_FILE_KEYS)}")
    unknown = sorted(set(data) - _FILE_KEYS)
    if unknown:
        raise ScenarioError(f"{source}: '{unknown[0]}': unknown key (known: {sorted(_FILE_KEYS)})")
    # counts first: bounded work before any element is looked at (docs/bad_input.md row 50)
    n_dyn = len(data["dynamic_vehicles"]) if isinstance(data.get("dynamic_vehicles"), list) else 0
    if n_dyn > MAX_DYNAMIC_VEHICLES:
        raise ScenarioError(f"{source}: dynamic_vehicles: {n_dyn} vehicles, at most {MAX_DYNAMIC_VEHICLES}")
    n_vac = len(data["vacant_spot_ids"]) if isinstance(data.get("vacant_spot_ids"), list) else 0
    if n_vac > lot.n_spots:
        raise ScenarioError(f"{source}: vacant_spot_ids: {n_vac} ids, but lot '{lot.name}' has {lot.n_spots} spots")
    seed = _integer(data.get("seed", seed), f"{source}: seed")
    reactive = data.get("reactive", reactive)
    if not isinstance(reactive, bool):
        raise ScenarioError(f"{source}: reactive: expected true/false, got {reactive!r}")
    ego_start = _ego_pose(lot, data.get("ego_start", list(params.ego_start)), f"{source}: ego_start", vehicle)
    entries = _ego_entries(lot, data.get("egos", []), source, vehicle)
    if "vacant_spot_ids" not in data:
        raise ScenarioError(f"{source}: vacant_spot_ids: missing")
    vac = data["vacant_spot_ids"]
    if not isinstance(vac, list):
        raise ScenarioError(f"{source}: vacant_spot_ids: expected a list of spot ids, got {vac!r}")
    vacant: list[int] = []
    seen: set[int] = set()
    for i, s in enumerate(vac):
        sid = _integer(s, f"{source}: vacant_spot_ids[{i}]")
        if not lot.has_spot(sid):
            raise ScenarioError(f"{source}: vacant_spot_ids[{i}]: unknown spot id {sid} (lot '{lot.name}')")
        if sid in seen:
            raise ScenarioError(f"{source}: vacant_spot_ids[{i}]: spot {sid} listed twice")
        vacant.append(sid)
        seen.add(sid)
    dyn_list = data.get("dynamic_vehicles", [])
    if not isinstance(dyn_list, list):
        raise ScenarioError(f"{source}: dynamic_vehicles: expected a list, got {type(dyn_list).__name__}")
    if len(dyn_list) > MAX_DYNAMIC_VEHICLES:
        raise ScenarioError(f"{source}: dynamic_vehicles: {len(dyn_list)} vehicles, at most {MAX_DYNAMIC_VEHICLES}")
    dynamic = _dynamic_vehicles(lot, dyn_list, seen, ego_start, source, reactive, params, vehicle)
    rng = np.random.default_rng(seed)
    parked: list[VehicleAgent] = []
    for s in lot.spots:
        flip = rng.random() < 0.5  # drawn for every spot so that headings do not depend on the vacant set
        if s.id in vacant:
            continue
        heading = s.heading + (math.pi if flip else 0.0)
        pose = np.array([s.x, s.y, math.atan2(math.sin(heading), math.cos(heading))])
        parked.append(VehicleAgent(id=s.id, length=params.parked_length, width=params.parked_width,
                                   initial_state=pose, controls=np.zeros((0, 2)), parked=True))
    return Scenario(seed=seed, reactive=reactive, ego_start=ego_start, ego=vehicle, vehicles=tuple(parked + dynamic),
                    dt=params.dt, t_hist=params.t_hist, passiveness_step=params.passiveness_step, ego_entries=entries)


def _ego_entries(lot: LotMap, egos, source: str, vehicle: VehicleSpec) -> tuple:
    """The ``egos`` entries: ((pose, entry time [s]), ...) of the automated cars after the first."""
    if not isinstance(egos, list):
        raise ScenarioError(f"{source}: egos: expected a list, got {type(egos).__name__}")
    if len(egos) > MAX_EGOS - 1:
        raise ScenarioError(f"{source}: egos: {len(egos)} egos besides ego_start's, at most {MAX_EGOS - 1}")
    out = []
    for j, e in enumerate(egos):
        w = f"{source}: egos[{j}]"
        _mapping(e, w, _EGO_KEYS)
        pose = _ego_pose(lot, e.get("start"), f"{w}.start", vehicle)
        out.append((pose, _number(e.get("enter_at", 0.0), f"{w}.enter_at", 0.0, 3600.0)))
    return tuple(out)


def _ego_pose(lot: LotMap, value, where: str, vehicle: VehicleSpec) -> np.ndarray:
    """An ego's pose [x, y, theta] whose footprint lies inside the lot."""
    if not isinstance(value, list) or len(value) != 3:
        raise ScenarioError(f"{where}: expected [x, y, theta], got {value!r}")
    pose = np.array([_number(x, f"{where}[{i}]") for i, x in enumerate(value)])
    if not polygon_contains_points(lot.boundary, rect_corners(pose, vehicle.length, vehicle.width)).all():
        raise ScenarioError(f"{where}: the ego's footprint is outside the lot")
    return pose


def _mapping(d, where: str, keys: set[str]) -> None:
    """``d`` is a mapping whose keys are among ``keys`` (ScenarioError naming the first unknown one)."""
    if not isinstance(d, dict):
        raise ScenarioError(f"{where}: expected a mapping with keys {sorted(keys)}")
    unknown = sorted(set(d) - keys)
    if unknown:
        raise ScenarioError(f"{where}.{unknown[0]}: unknown key (known: {sorted(keys)})")


def _dynamic_vehicles(lot: LotMap, dyn_list: list, seen: set[int], ego_start: np.ndarray, source: str,
                      reactive: bool, params: ScenarioParams, vehicle: VehicleSpec) -> list[VehicleAgent]:
    """The ``dynamic_vehicles`` entries, each checked and built (targets among the vacant ``seen`` spots)."""
    names = {"/".join(k): k for k in ALL_MANEUVERS}
    dynamic: list[VehicleAgent] = []
    plans: dict[int, np.ndarray] = {}
    for j, d in enumerate(dyn_list):
        w = f"{source}: dynamic_vehicles[{j}]"
        _mapping(d, w, _DYN_KEYS)
        for key in ("target_spot", "maneuver"):
            if key not in d:
                raise ScenarioError(f"{w}.{key}: missing")
        spot = _integer(d["target_spot"], f"{w}.target_spot")
        if spot not in seen:
            raise ScenarioError(f"{w}.target_spot: spot {spot} is not in vacant_spot_ids")
        if spot in {a.target_spot_id for a in dynamic}:
            raise ScenarioError(f"{w}.target_spot: spot {spot} is already the target of another vehicle")
        if d["maneuver"] not in names:
            raise ScenarioError(f"{w}.maneuver: {d['maneuver']!r} is not one of {sorted(names)}")
        v_c = _number(d.get("cruise_speed", sum(params.cruise_speed) / 2), f"{w}.cruise_speed", 0.1, 5.0)
        approach = _number(d.get("approach_distance", 0.0), f"{w}.approach_distance", 0.0, 50.0)
        n_pass = _integer(d.get("passiveness", params.passiveness[0]), f"{w}.passiveness", 0, 100)
        agent = build_dynamic_vehicle(lot, 1000 + j, spot, names[d["maneuver"]], v_c, approach, params, vehicle)
        if not _valid_dynamic(lot, agent, ego_start, vehicle, params, dynamic, plans):
            raise ScenarioError(f"{w}: its plan leaves the lot, starts on the ego or collides with another "
                                f"dynamic vehicle's plan")
        dynamic.append(replace(agent, passiveness=n_pass if reactive else 0))
    return dynamic


def load_scenario_file(lot: LotMap, path, seed: int, reactive: bool, params: ScenarioParams = ScenarioParams(),
                       vehicle: VehicleSpec = VehicleSpec()) -> Scenario:
    """Read a scenario YAML file (see :func:`scenario_from_dict`; example: avp_sim/scenarios/two_cars.yaml)."""
    from pathlib import Path

    from avp_sim.core.scenario_source import parse_scenario_text

    p = Path(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise ScenarioError(f"{p}: no such scenario file") from None
    except OSError as exc:
        raise ScenarioError(f"{p}: cannot read ({exc.strerror})") from None
    try:
        data = parse_scenario_text(raw, str(p), max(len(raw), 1))
    except ScenarioError as exc:  # the message names the file; it never quotes the file's content
        raise ScenarioError(str(exc)) from None
    return scenario_from_dict(lot, data, str(p), seed, reactive, params, vehicle)

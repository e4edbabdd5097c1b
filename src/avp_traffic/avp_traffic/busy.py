"""The ``busy`` scenario family: a lot as busy as the DLP dataset's, beyond the paper's experiment.

The paper names as limitations of its experiment the small lot, no pedestrians and no exiting vehicles (§VII).
A busy episode has all three, on any lot (the whole DLP lot, ``dlp_lot.yaml``, is the one it is meant for):

* **vehicles**: the traffic generator of :mod:`.traffic` — parkers that queue outside the entrance, drive the
  right-hand lanes to a spot and park with one of ParkSim's 8 maneuvers (most choose their spot at the entrance,
  a share explores), and **leavers** that unpark (a maneuver backwards) and drive to the exit; arrivals and
  departures are Poisson processes, so spots free and fill during the episode. Occupancy at the start, the
  arrival and departure rates are :class:`BusyParams` (defaults: 20+ cars moving in a 60 s DLP episode);
* **pedestrians** (eq. 2): each walks along the aisles, along the parked cars (``ped_edge_offset`` inside the
  road's edge), between the entrance and a
  parked car — from the gate to the car (and stays there: gets in) or from the car out through the gate —
  at U[``ped_speed``], starting at a random time;
* **the ego** starts where the lot's scenario roles put it (:mod:`avp_world.lot_scenario`: at the entrance), in
  the right-hand lane (``ego_in_lane``; the paper's ego starts on the centre line, "at the top of the middle
  road" — in a busy lot cars enter and leave past it, and on the centre line it blocks both lanes).
  Traffic and walks whose footprints come within ``ego_clearance`` of the ego's start footprint between
  t = -t_hist and t = ``clear_time`` are left out (the ego must be able to start), others drive past it later
  (reactive agents brake for it, §III-B).

Same seed ⇒ same episode (reactive and non-reactive share the set-up; non-reactive zeroes the passiveness).
Everything is seeded from ``seed`` alone: the family never looks at which method runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from avp_scenario.scenario import PedestrianAgent, Scenario, ScenarioError
from avp_traffic.traffic import TrafficGenerator, TrafficParams
from avp_world.geometry import disc_rect_overlap, polygon_contains_points, rect_corners, rects_overlap
from avp_world.lot import LotMap
from avp_world.lot_scenario import lot_scenario
from avp_world.vehicle import VehicleSpec

PED_ID0 = 20000  # ids of the pedestrians


@dataclass(frozen=True)
class BusyParams:
    """Knobs of the busy family (module docstring); times in s, distances in m, speeds in m/s."""

    occupancy: tuple[float, float] = (0.75, 0.9)  # share of spots taken at the start (drawn per episode)
    arrival_gap: tuple[float, float] = (2.0, 4.0)  # mean gap between arrivals at the gate, drawn per episode
    departure_gap: tuple[float, float] = (3.0, 6.0)  # mean gap between departures
    n_pedestrians: tuple[int, int] = (10, 16)
    ped_speed: tuple[float, float] = (0.8, 1.4)
    ped_radius: float = 0.3
    ped_edge_offset: float = 0.1  # pedestrians' centres walk this far inside the road's edge (along the parked cars)
    ego_in_lane: bool = True  # the ego starts in the right-hand lane of its road, not on the centre line (§VI-A)
    ped_to_gate_share: float = 0.5  # share walking from a car out through the gate (the rest walk to a car)
    clear_time: float = 3.0  # the ego's start stays clear of traffic and walkers until then
    ego_clearance: float = 0.5
    t_pre: float = 40.0  # traffic simulated before the episode's history (cars already on their way at t = 0)


_GENERATORS: dict[tuple, TrafficGenerator] = {}  # per (lot, traffic params): the lane graph is built once


def _generator(lot: LotMap, tp: TrafficParams, vehicle: VehicleSpec) -> TrafficGenerator:
    key = (lot.source, lot.sha256, tp, vehicle)
    if key not in _GENERATORS:
        if len(_GENERATORS) >= 4:
            _GENERATORS.clear()
        _GENERATORS[key] = TrafficGenerator(lot, tp, vehicle)
    return _GENERATORS[key]


def generate_busy_scenario(lot: LotMap, seed: int, reactive: bool, dt: float = 0.1, t_hist: float = 4.0,
                           t_final: float = 60.0, busy: BusyParams = BusyParams(),
                           vehicle: VehicleSpec = VehicleSpec()) -> Scenario:
    """One busy episode (module docstring); ScenarioError when the lot cannot hold one."""
    tp = TrafficParams(dt=dt, t_hist=t_hist, t_final=t_final, t_pre=busy.t_pre, occupancy=busy.occupancy,
                       arrival_gap=busy.arrival_gap, departure_gap=busy.departure_gap)
    try:
        gen = _generator(lot, tp, vehicle)
        roles = lot_scenario(lot)
        ego_start = np.asarray(roles.ego_start, dtype=float)
        if busy.ego_in_lane:  # two-way traffic passes the ego's start: it waits in its lane like the other cars
            right = np.array([math.sin(ego_start[2]), -math.cos(ego_start[2])])
            ego_start[:2] += right * roles.aisle_width / 4.0
        traffic = gen.generate(int(seed), ego_start=ego_start, ego_tour=False)
    except (ValueError, RuntimeError) as exc:
        raise ScenarioError(f"busy scenario on lot '{lot.name}', seed {seed}: {exc}") from None
    sc = traffic.scenario
    hist = int(round(t_hist / dt))
    n_clear = hist + int(round(busy.clear_time / dt)) + 1
    ego_fp = rect_corners(ego_start, vehicle.length, vehicle.width)
    keep = []
    for v in sc.vehicles:
        states = _states(v.initial_state, v.controls, dt, n_clear)
        if not rects_overlap(rect_corners(states, v.length, v.width), ego_fp[None], busy.ego_clearance).any():
            keep.append(v if reactive else replace(v, passiveness=0))
    rng = np.random.default_rng([int(seed), 1])  # the walkers' own stream: vehicles do not change with them
    peds = _pedestrians(lot, gen, rng, busy, keep, ego_fp, dt, hist, n_clear, t_final, reactive)
    return replace(sc, seed=int(seed), reactive=bool(reactive), ego_start=ego_start, vehicles=tuple(keep),
                   pedestrians=tuple(peds))


def _states(x0: np.ndarray, controls: np.ndarray, dt: float, n: int) -> np.ndarray:
    """The first ``n`` states of eq. (1) from ``x0`` (standing still after the plan ends)."""
    from avp_world.kinematics import rollout_vehicle

    u = np.zeros((n - 1, 2))
    m = min(len(controls), n - 1)
    u[:m] = controls[:m]
    return rollout_vehicle(np.asarray(x0, dtype=float), u, dt)


def _walk_polyline(lot: LotMap, gen: TrafficGenerator, row: int, edge: float) -> np.ndarray | None:
    """(K, 2) points from 3 m outside the gate along the lanes to the front of spot ``row``, ``edge`` m inside
    the right edge of each road; None when the spot has no lane."""
    g = gen.graph
    options = gen.spot_lanes.get(row)
    if not options:
        return None
    lane, t_spot, _ = options[0]
    try:
        route = g.shortest(g.entry, lane)
    except ValueError:
        return None
    pts: list[np.ndarray] = []
    for k, lid in enumerate(route):
        ln = g.lanes[lid]
        right = np.array([ln.d[1], -ln.d[0]])
        shift = right * max(0.0, ln.width / 4.0 - edge)
        t0 = -3.0 if k == 0 else 0.0  # the walk starts 3 m outside the gate (the entry lane starts at it)
        t1 = t_spot if k == len(route) - 1 else ln.length
        pts += [ln.point(t0) + shift, ln.point(t1) + shift]
    spot = lot.spot_poses[row]
    u = np.array([math.cos(spot[2]), math.sin(spot[2])])
    pts.append(spot[:2] - u * (0.5 * lot.spot_dims[row, 0] - 0.6))  # at the car's front, inside the spot
    out = [pts[0]]
    for p in pts[1:]:
        if np.hypot(*(p - out[-1])) > 1e-6:
            out.append(p)
    return np.asarray(out)


def _walk_controls(poly: np.ndarray, speed: float, dt: float) -> np.ndarray:
    """(T, 2) controls (v, theta) of eq. (2) walking ``poly`` at ``speed``; the last step of each leg is shorter,
    so every corner is reached exactly."""
    rows: list[tuple[float, float]] = []
    for d in np.diff(poly, axis=0):
        length, th = float(np.hypot(*d)), math.atan2(d[1], d[0])
        n = int(length // (speed * dt))
        rows += [(speed, th)] * n
        rest = length - n * speed * dt
        if rest > 1e-9:
            rows.append((rest / dt, th))
    return np.asarray(rows, dtype=float).reshape(-1, 2)


def _pedestrians(lot: LotMap, gen: TrafficGenerator, rng: np.random.Generator, busy: BusyParams, vehicles, ego_fp,
                 dt: float, hist: int, n_clear: int, t_final: float, reactive: bool) -> list[PedestrianAgent]:
    parked_rows = [lot.spot_index(v.id) for v in vehicles if v.parked and lot.has_spot(v.id)]
    if not parked_rows:
        return []
    n = int(rng.integers(busy.n_pedestrians[0], busy.n_pedestrians[1] + 1))
    out: list[PedestrianAgent] = []
    for _ in range(20 * n):
        if len(out) >= n:
            break
        row = int(rng.choice(parked_rows))
        poly = _walk_polyline(lot, gen, row, busy.ped_edge_offset)
        to_gate = rng.random() < busy.ped_to_gate_share
        speed = float(rng.uniform(*busy.ped_speed))
        start = int(rng.integers(0, hist + int(0.6 * t_final / dt)))
        passiveness = int(rng.integers(2, 7))
        if poly is None:
            continue
        if to_gate:
            poly = poly[::-1]
        walk = _walk_controls(poly, speed, dt)
        controls = np.concatenate([np.tile([0.0, walk[0, 1]], (start, 1)), walk])
        pos = poly[0] + np.concatenate([[[0.0, 0.0]], np.cumsum(controls[:n_clear - 1, :1] * np.stack(
            [np.cos(controls[:n_clear - 1, 1]), np.sin(controls[:n_clear - 1, 1])], axis=1) * dt, axis=0)])
        if disc_rect_overlap(pos, np.full(len(pos), busy.ped_radius + busy.ego_clearance), ego_fp[None]).any():
            continue
        if not polygon_contains_points(lot.boundary, poly[1:-1]).all():
            continue
        out.append(PedestrianAgent(id=PED_ID0 + len(out), radius=busy.ped_radius, initial_position=poly[0].copy(),
                                   controls=controls, passiveness=passiveness if reactive else 0))
    return out

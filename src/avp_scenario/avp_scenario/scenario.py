"""Seeded scenarios of the paper's experiment (§VI-A) and YAML scenario files.

A scenario fixes everything random about an episode: which spots hold parked cars, the dynamic
vehicles (target spot, one of ParkSim's 8 maneuvers, approach speed and distance), passiveness
(reactive mode, §III-B) and the ego's start. Same seed ⇒ identical scenario.

Every non-ego agent gets a predefined plan of controls for eq. (1)/(2) starting t_hist before t = 0,
so that a 4 s history exists at t = 0 (§III-B).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from avp_scenario.maneuvers import ALL_MANEUVERS, ManeuverKey, SceneGeometry, generate_maneuver, maneuver_to_world
from avp_world.geometry import polygon_contains_points, rect_corners, rects_overlap
from avp_world.kinematics import rollout_vehicle
from avp_world.lot import LotMap
from avp_world.lot_scenario import lot_scenario
from avp_world.vehicle import VehicleSpec


class ScenarioError(ValueError):
    """A scenario could not be built or a scenario file is malformed."""


@dataclass(frozen=True)
class VehicleAgent:
    """A non-ego vehicle: plan = controls (v, omega) from t = -t_hist on; zeros after the plan ends."""

    id: int
    length: float
    width: float
    initial_state: np.ndarray  # (3,) at t = -t_hist
    controls: np.ndarray  # (T, 2)
    passiveness: int = 0  # n_pass (§III-B); 0 = non-reactive
    target_spot_id: int = -1  # the spot its plan parks in (dynamic vehicles), -1 otherwise
    maneuver: str = ""  # e.g. "near/before/head_in"
    parked: bool = False


@dataclass(frozen=True)
class PedestrianAgent:
    """A pedestrian disc with a plan of controls (v, theta) for eq. (2) from t = -t_hist on."""

    id: int
    radius: float
    initial_position: np.ndarray  # (2,)
    controls: np.ndarray  # (T, 2)
    passiveness: int = 0


@dataclass(frozen=True)
class Scenario:
    seed: int
    reactive: bool
    ego_start: np.ndarray  # (3,)
    ego: VehicleSpec
    vehicles: tuple[VehicleAgent, ...]
    pedestrians: tuple[PedestrianAgent, ...] = ()
    dt: float = 0.1
    t_hist: float = 4.0
    passiveness_step: float = 0.1  # s per unit of n_pass (§III-B counts timesteps; see ScenarioParams)
    # further egos of a scenario file ((pose (3,), entry time [s]) each; .egos): the lot then has 1 + len egos
    ego_entries: tuple = ()

    @property
    def hist_steps(self) -> int:
        return int(round(self.t_hist / self.dt))

    @property
    def passiveness_unit_steps(self) -> int:
        """Simulator steps per unit of passiveness (>= 1)."""
        return max(1, int(round(self.passiveness_step / self.dt)))

    def dynamic_vehicles(self) -> tuple[VehicleAgent, ...]:
        return tuple(v for v in self.vehicles if not v.parked)


@dataclass(frozen=True)
class ScenarioParams:
    """Knobs of the §VI-A generator (defaults: our reading of the paper's protocol, see docs/world.md).

    Where the ego starts, which spots are contested, the groups the fallbacks are drawn from and the aisle width
    of the maneuvers come from the lot (its ``scenario:`` block or its geometry, :mod:`avp_world.lot_scenario`)
    where they are None here; :meth:`resolve` fills them in. ``fallback_rows`` (first, last): the positions in
    each fallback group one vacant spot is drawn from (groups run from the far end of the ego's road; on the paper
    lot rows 0-4, the rows of the contested spots, docs/world.md; (0, 9) is the earlier reading "anywhere in the
    outer columns"). ``outer_spot_groups``, if set, replaces the sliced groups.

    ``maneuver_max_speed`` / ``maneuver_max_accel``: bounds of the time
    parameterisation of ParkSim's 8 maneuvers; 1.1 m/s with 2 m/s^2 gives the library a mean speed of
    1.0 m/s, the pace of ParkSim's H-OBCA library (its horizon N is the number of Hybrid A* warm-start
    samples, 0.1 m apart, at dt = 0.1 s, so a maneuver of L metres lasts about L seconds). 2.0 m/s was the
    earlier reading (ParkSim's speed bound used as the pace).

    ``passiveness_step``: the length of one unit of passiveness n_pass. §III-B counts it in timesteps Δt; the
    default 0.1 s is the simulator's Δt (look-ahead 0.2-0.6 s for n_pass 2-6). §VI-A takes "unmentioned
    variables" from Nawaz et al., whose timestep is 0.5 s (look-ahead 1-3 s): ``avp experiment --protocol paper``.
    ``approach_distance``: metres each dynamic vehicle still has to drive to its maneuver's start at t = 0 (drawn
    uniformly); ``cruise_speed``: its lane speed before braking there. ``spawn_closer_than_ego``: re-draw a
    vehicle whose centre at t = 0 is not nearer its target spot than the ego's start is (§VI-B: "all dynamic
    agents were initialized closer to their intended spots").
    """

    contested_spot_ids: tuple[int, ...] | None = None  # None: the lot's (paper lot: 10-14, 20-24)
    outer_spot_groups: tuple[tuple[int, ...], ...] | None = None  # None: the lot's groups, rows fallback_rows
    fallback_rows: tuple[int, int] = (0, 4)
    n_dynamic: tuple[int, int] = (1, 2)
    passiveness: tuple[int, int] = (2, 6)
    cruise_speed: tuple[float, float] = (1.5, 2.5)  # m/s before braking for the maneuver start
    approach_distance: tuple[float, float] = (0.0, 8.0)  # m left to the maneuver start at t = 0
    braking_decel: float = 1.5  # m/s^2 when stopping at the maneuver start
    maneuver_max_speed: float = 1.1  # m/s, |v| bound of the maneuvers' time parameterisation (mean 1.0 m/s)
    maneuver_max_accel: float = 2.0  # m/s^2, |dv/dt| bound of the maneuvers (ParkSim a_max_parking)
    ego_start: tuple[float, float, float] | None = None  # None: the lot's (paper lot: (21.5, 38.0, -pi/2))
    ego_clearance: float = 1.0  # m between a dynamic vehicle at t = 0 and the ego's start footprint
    aisle_width: float | None = None  # None: the lot's (its first road's width; paper lot 7.0)
    parked_length: float = 4.6
    parked_width: float = 1.85
    dt: float = 0.1
    t_hist: float = 4.0
    t_final: float = 100.0
    max_attempts: int = 200
    passiveness_step: float = 0.1  # s per unit of n_pass (0.5 = Nawaz et al.'s timestep)
    spawn_closer_than_ego: bool = False  # §VI-B: agents start nearer their spot than the ego

    def resolve(self, lot: LotMap) -> ScenarioParams:
        """These parameters with every lot-dependent one that is None taken from ``lot``
        (:func:`avp_world.lot_scenario.lot_scenario`); ScenarioError for bad fallback rows."""
        lo, hi = self.fallback_rows
        if not 0 <= lo <= hi:
            raise ScenarioError(f"fallback rows: need 0 <= first <= last, got {lo}, {hi}")
        ls = lot_scenario(lot)
        groups = self.outer_spot_groups
        if groups is None:
            groups = tuple(g[lo:hi + 1] for g in ls.fallback_spot_groups if g[lo:hi + 1])
        return replace(self, outer_spot_groups=groups,
                       contested_spot_ids=ls.contested_spot_ids if self.contested_spot_ids is None
                       else self.contested_spot_ids,
                       ego_start=ls.ego_start if self.ego_start is None else self.ego_start,
                       aisle_width=ls.aisle_width if self.aisle_width is None else self.aisle_width)


def _cruise_controls(distance: float, v_cruise: float, decel: float, dt: float) -> np.ndarray:
    """Straight-line speeds that cover ``distance`` exactly, cruising then braking to 0 (omega = 0)."""
    if distance <= 1e-9:
        return np.zeros((0, 2))
    brake_d = v_cruise**2 / (2 * decel)
    speeds: list[float] = []
    s = 0.0
    while s < distance - 1e-9:
        remaining = distance - s
        v = v_cruise if remaining > brake_d else max(math.sqrt(2 * decel * remaining), 0.2)
        v = min(v, remaining / dt)
        speeds.append(v)
        s += v * dt
    out = np.zeros((len(speeds), 2))
    out[:, 0] = speeds
    out[-1, 0] += (distance - s) / dt  # exact total distance
    return out


def _footprints(states: np.ndarray, length: float, width: float) -> np.ndarray:
    return rect_corners(states, length, width)


def build_dynamic_vehicle(
    lot: LotMap,
    agent_id: int,
    spot_id: int,
    key: ManeuverKey,
    v_cruise: float,
    approach: float,
    params: ScenarioParams,
    vehicle: VehicleSpec,
) -> VehicleAgent:
    """A dynamic vehicle that cruises in its lane, stops at the maneuver start and parks in ``spot_id``.

    ``approach`` is the distance still to drive to the maneuver start at t = 0.
    """
    k = lot.spot_index(spot_id)
    scene = SceneGeometry(aisle_width=params.aisle_width, spot_length=float(lot.spot_dims[k, 0]),
                          spot_width=float(lot.spot_dims[k, 1]))
    man = generate_maneuver(key, scene, vehicle, params.dt, params.maneuver_max_speed, params.maneuver_max_accel)
    start_world, _ = maneuver_to_world(man, lot.spot_poses[k], params.aisle_width, key.side)
    # find the cruise length such that at t = 0 (after hist_steps) `approach` metres remain
    hist = int(round(params.t_hist / params.dt))
    lo, hi = approach, approach + v_cruise * params.t_hist + 1.0
    cruise = _cruise_controls(hi, v_cruise, params.braking_decel, params.dt)
    for _ in range(40):  # bisection on the total cruise distance
        mid = 0.5 * (lo + hi)
        cruise = _cruise_controls(mid, v_cruise, params.braking_decel, params.dt)
        travelled = float(np.sum(cruise[:hist, 0]) * params.dt)
        if mid - travelled > approach:
            hi = mid
        else:
            lo = mid
    total = float(np.sum(cruise[:, 0]) * params.dt)
    heading = float(start_world[2])
    spawn = np.array([start_world[0] - total * math.cos(heading), start_world[1] - total * math.sin(heading), heading])
    controls = np.concatenate([cruise, man.controls], axis=0)
    if len(controls) < hist:  # plan must at least cover the history
        controls = np.concatenate([np.zeros((hist - len(controls), 2)), controls])
    return VehicleAgent(
        id=agent_id,
        length=vehicle.length,
        width=vehicle.width,
        initial_state=spawn,
        controls=controls,
        target_spot_id=int(spot_id),
        maneuver="/".join(key),
    )


def plan_states(agent: VehicleAgent, n_steps: int | None = None, dt: float = 0.1) -> np.ndarray:
    """States of an unobstructed agent following its plan from t = -t_hist (length T + 1)."""
    controls = agent.controls if n_steps is None else agent.controls[:n_steps]
    return rollout_vehicle(agent.initial_state, controls, dt)


def _valid_dynamic(lot: LotMap, agent: VehicleAgent, ego_start: np.ndarray, ego: VehicleSpec,
                   params: ScenarioParams, others: list[VehicleAgent],
                   plans: dict[int, np.ndarray] | None = None) -> bool:
    """Whether ``agent``'s plan stays in the lot, starts clear of the ego and never meets the plans of ``others``.
    ``plans``: the accepted agents' rolled-out states by vehicle id, filled as they are met (a request
    of n vehicles then rolls out n plans, not n^2/2); pairs whose whole sweeps are apart are not tested further."""
    hist = int(round(params.t_hist / params.dt))
    states = plan_states(agent, dt=params.dt)
    fp = _footprints(states, agent.length, agent.width)
    if not polygon_contains_points(lot.boundary, fp.reshape(-1, 2)).all():
        return False
    ego_fp = rect_corners(ego_start, ego.length, ego.width)
    if rects_overlap(fp[hist], ego_fp, margin=params.ego_clearance):
        return False
    if params.spawn_closer_than_ego and agent.target_spot_id >= 0:
        spot = lot.spot_poses[lot.spot_index(agent.target_spot_id)][:2]
        if np.hypot(*(states[hist, :2] - spot)) >= np.hypot(*(ego_start[:2] - spot)):
            return False
    plans = {} if plans is None else plans
    lo, hi = fp.reshape(-1, 2).min(0) - 0.2, fp.reshape(-1, 2).max(0) + 0.2  # the sweep's box, with the margin
    for other in others:
        if other.id not in plans:
            plans[other.id] = plan_states(other, dt=params.dt)
        o = plans[other.id]
        # a corner of any footprint lies within half a diagonal of its centre: apart boxes cannot overlap
        r = 0.5 * math.hypot(other.length, other.width)
        if (o[:, :2].min(0) - r > hi).any() or (o[:, :2].max(0) + r < lo).any():
            continue
        n = max(len(o), len(states))
        a = np.concatenate([states, np.repeat(states[-1:], n - len(states), 0)])
        b = np.concatenate([o, np.repeat(o[-1:], n - len(o), 0)])
        if rects_overlap(_footprints(a, agent.length, agent.width), _footprints(b, other.length, other.width),
                         margin=0.2).any():
            return False
    return True


def generate_paper_scenario(
    lot: LotMap, seed: int, reactive: bool, params: ScenarioParams = ScenarioParams(),
    vehicle: VehicleSpec = VehicleSpec(),
) -> Scenario:
    """The §VI-A protocol: parked cars everywhere except some contested bottom spots and 2 outer spots;
    1-2 dynamic vehicles each assigned a vacant contested spot and a random maneuver (re-drawn while
    plans collide); passiveness ~ U{2..6} when reactive, else 0; ego at the top of the middle road."""
    params = params.resolve(lot)
    rng = np.random.default_rng(int(seed))
    for cid in (*params.contested_spot_ids, *[s for g in params.outer_spot_groups for s in g]):
        lot.spot_index(cid)  # KeyError names an unknown id
    n_dyn = int(rng.integers(params.n_dynamic[0], params.n_dynamic[1] + 1))
    n_vacant = int(rng.integers(n_dyn, len(params.contested_spot_ids) + 1))
    vacant = [int(s) for s in rng.choice(params.contested_spot_ids, size=n_vacant, replace=False)]
    outer: list[int] = []
    for group in params.outer_spot_groups:  # distinct spots where groups share some (one-sided lots)
        left = [s for s in group if s not in outer and s not in vacant]
        if left:
            outer.append(int(rng.choice(left)))
    ego_start = np.array(params.ego_start, dtype=float)

    dynamic: list[VehicleAgent] = []
    plans: dict[int, np.ndarray] = {}
    attempts = 0
    while len(dynamic) < n_dyn:
        attempts += 1
        if attempts > params.max_attempts:
            raise ScenarioError(f"seed {seed}: no collision-free plans for {n_dyn} dynamic vehicles")
        free = [s for s in vacant if s not in {d.target_spot_id for d in dynamic}]
        spot = int(rng.choice(free))
        key = ALL_MANEUVERS[int(rng.integers(len(ALL_MANEUVERS)))]
        v_c = float(rng.uniform(*params.cruise_speed))
        approach = float(rng.uniform(*params.approach_distance))
        agent = build_dynamic_vehicle(lot, 1000 + len(dynamic), spot, key, v_c, approach, params, vehicle)
        if _valid_dynamic(lot, agent, ego_start, vehicle, params, dynamic, plans):
            dynamic.append(agent)
    # drawn in both modes so that reactive and non-reactive runs of a seed share the same setup (§VI-B)
    passiveness = [int(rng.integers(params.passiveness[0], params.passiveness[1] + 1)) for _ in dynamic]
    dynamic = [replace(d, passiveness=n if reactive else 0) for d, n in zip(dynamic, passiveness, strict=True)]

    parked: list[VehicleAgent] = []
    empty = set(vacant) | set(outer)
    for s in lot.spots:
        if s.id in empty:
            continue
        heading = s.heading + (math.pi if rng.random() < 0.5 else 0.0)
        pose = np.array([s.x, s.y, math.atan2(math.sin(heading), math.cos(heading))])
        parked.append(VehicleAgent(id=s.id, length=params.parked_length, width=params.parked_width,
                                   initial_state=pose, controls=np.zeros((0, 2)), parked=True))
    return Scenario(seed=int(seed), reactive=bool(reactive), ego_start=ego_start, ego=vehicle,
                    vehicles=tuple(parked + dynamic), dt=params.dt, t_hist=params.t_hist,
                    passiveness_step=params.passiveness_step)


@dataclass
class ScenarioSummary:
    """Human-readable summary (for logs and the demo)."""

    seed: int
    reactive: bool
    n_parked: int
    dynamic: list[dict] = field(default_factory=list)

    @classmethod
    def of(cls, sc: Scenario) -> ScenarioSummary:
        return cls(sc.seed, sc.reactive, sum(v.parked for v in sc.vehicles),
                   [{"id": v.id, "target_spot": v.target_spot_id, "maneuver": v.maneuver,
                     "passiveness": v.passiveness} for v in sc.dynamic_vehicles()])


# ------------------------------------------------------------------------------------------ scenario files

"""One episode of the simulated parking lot: reactive agents (§III-B), observations (§III-A), metrics (§VI-B).

Step order at time t (k = t / dt):
  1. :meth:`World.observe` returns the ego's observation of the state at t;
  2. :meth:`World.step` takes the ego command u_0,t; each other agent A brakes (u = 0) if its next
     n_pass,A planned footprints A_{t+dt..t+n_pass dt} meet the ego's current footprint V_0,t, else takes
     its next unused planned control (§III-B);
  3. with ``agents_yield`` (off by default; :mod:`.agent_yield`) the agents also brake for each other by the same
     rule;
  4. everyone moves by eq. (1) / eq. (2); collisions and parking are checked at t + dt.

With K egos (``egos.count``, :mod:`.egos`) :meth:`World.observe` takes the ego's index, :meth:`World.step_all` one
command per ego, each agent brakes for every ego in the lot, and each ego keeps its own status and metrics; with K = 1
everything is as above.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from avp_scenario.scenario import Scenario
from avp_sensing.observation import RayCaster, SensorConfig, classify_world
from avp_sensing.occupancy import OccupancyTracker
from avp_sim.core.egos import EGO_ID_BASE, Egos
from avp_sim.core.metrics import COLLISION, RUNNING, SUCCESS, TIMEOUT, EpisodeMetrics, apply_event, step_event
from avp_traffic.agent_yield import agents_yield, plan_lookahead
from avp_world.geometry import disc_rect_overlap, rect_corners, rects_overlap
from avp_world.kinematics import step_pedestrian, step_vehicle
from avp_world.lot import LotMap
from avp_world.types import Observation, ObservedPedestrian, ObservedVehicle

__all__ = ["World", "WorldConfig", "EpisodeMetrics", "RUNNING", "SUCCESS", "COLLISION", "TIMEOUT"]


def _control_table(controls: list[np.ndarray], t_steps: int) -> np.ndarray:
    """(N, t_steps, 2) planned controls of N agents, zero (stand still) after each plan's end."""
    out = np.zeros((len(controls), t_steps, 2))
    for i, c in enumerate(controls):
        m = min(len(c), t_steps)
        out[i, :m] = c[:m]
    return out


@dataclass(frozen=True)
class WorldConfig:
    t_final: float = 100.0  # t_f [s] (§VI-A)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    ego_max_speed: float = 5.0  # |v| of the ego is clipped to this [m/s]
    agents_yield: bool = False  # agents also brake for each other (§III-B: for the ego only; .agent_yield)
    n_egos: int = 1  # K automated cars in the lot (egos.count; .egos); 1 = the paper
    entry_interval: float = 5.0  # s between two egos' entries through the gate (egos.entry_interval)
    entry_clearance: float = 1.0  # m: nothing within this of the start footprint for the gate to be clear
    n_drivers: int = 0  # D cars driven from outside (drivers.count; .egos, docs/teleop.md)
    driver_enter_at: float = 0.0  # s: when the first driven car may enter (drivers.enter_at)
    driver_poses: tuple = ()  # where driven car j enters ((x, y, theta) each; none: the gate) (drivers.poses)


class World:
    """Ground-truth state of one episode. Deterministic given the scenario and the ego commands."""

    def __init__(self, lot: LotMap, scenario: Scenario, config: WorldConfig = WorldConfig()):
        self.lot = lot
        self.scenario = scenario
        self.config = config
        self.dt = scenario.dt
        self.hist = scenario.hist_steps
        self.caster = RayCaster(lot, config.sensor)
        sc = scenario
        n = len(sc.vehicles)
        self.vehicle_ids = np.array([v.id for v in sc.vehicles], dtype=np.int64)
        self.vehicle_dims = np.array([[v.length, v.width] for v in sc.vehicles]).reshape(n, 2)
        # n_pass in units of scenario.passiveness_step -> look-ahead in simulator steps (§III-B)
        self.passiveness = np.array([v.passiveness for v in sc.vehicles], dtype=np.int64) * sc.passiveness_unit_steps
        self.target_spot = np.array([v.target_spot_id for v in sc.vehicles], dtype=np.int64)
        self.is_dynamic = np.array([not v.parked for v in sc.vehicles], dtype=bool)
        t_steps = int(round(config.t_final / self.dt)) + self.hist + int(self.passiveness.max(initial=0)) + 2
        self.plans = _control_table([v.controls for v in sc.vehicles], t_steps)
        self.plan_index = np.zeros(n, dtype=np.int64)
        self.states = np.array([v.initial_state for v in sc.vehicles], dtype=float).reshape(n, 3)
        # how far an agent's centre may be from the ego's for A_tau to meet V_0 within its n_pass steps: the
        # two circumradii plus the farthest its plan can carry it (|v| dt per step, eq. 1)
        self._brake_reach = (np.abs(self.plans[:, :, 0]).max(axis=1, initial=0.0) * self.passiveness * self.dt
                             + 0.5 * np.hypot(self.vehicle_dims[:, 0], self.vehicle_dims[:, 1])
                             + 0.5 * math.hypot(sc.ego.length, sc.ego.width) + 1e-6)
        # pedestrians
        p = len(sc.pedestrians)
        self.ped_ids = np.array([q.id for q in sc.pedestrians], dtype=np.int64)
        self.ped_radii = np.array([q.radius for q in sc.pedestrians], dtype=float)
        self.ped_pass = np.array([q.passiveness for q in sc.pedestrians], dtype=np.int64) * sc.passiveness_unit_steps
        self.ped_plans = _control_table([q.controls for q in sc.pedestrians], t_steps)
        self.ped_index = np.zeros(p, dtype=np.int64)
        self.ped_pos = np.array([q.initial_position for q in sc.pedestrians], dtype=float).reshape(p, 2)
        self.ped_prev = self.ped_pos.copy()
        # history buffer: (n, hist + 1, 3); filled by replaying the plans from t = -t_hist to t = 0
        self.history = np.zeros((n, self.hist + 1, 3))
        self.history[:, 0] = self.states
        for k in range(self.hist):
            self._advance_agents(np.zeros(n, dtype=bool), np.zeros(p, dtype=bool))
            self.history[:, k + 1] = self.states
        self.step_index = 0
        self._occupancy_step = -1  # occupancy() cache: state changes only in step()
        self._tracker = OccupancyTracker(lot)  # occupancy(): tests again only the vehicles that moved
        self.egos = Egos(np.array(sc.ego_start, dtype=float), config.n_egos,
                         int(round(config.entry_interval / self.dt)), self.hist, sc.ego.length, sc.ego.width,
                         tuple((pose, int(round(t / self.dt))) for pose, t in sc.ego_entries),
                         config.n_drivers, int(round(config.driver_enter_at / self.dt)), config.driver_poses)
        self.status = RUNNING
        self.braking = np.zeros(n, dtype=bool)  # braking for the ego (§III-B)
        self.braking_for = np.zeros((n, self.egos.count), dtype=bool)  # ... for which ego (set by each step)
        self.ped_braking = np.zeros(p, dtype=bool)
        self.yielding = np.zeros(n, dtype=bool)  # braking for another agent only (agents_yield)
        self.ped_yielding = np.zeros(p, dtype=bool)
        self.log_ego: list[np.ndarray] = [self.ego.copy()]
        self.log_vehicles: list[np.ndarray] = [self.states.copy()]
        self.log_braking: list[np.ndarray] = [self.braking.copy()]
        self.log_commands: list[np.ndarray] = []
        self.log_egos: list[np.ndarray] = [self.egos.poses.copy()]
        self.last_scan = None  # the RayScan of the latest observe() (avp_sensing.noisy reads it)
        self._check_events()

    # ------------------------------------------------------------------ ego 0 (the paper's one ego)
    @property
    def ego(self) -> np.ndarray:
        """Ego 0's pose (x, y, theta): the one ego of the paper."""
        return self.egos.poses[0]

    @property
    def ego_speed(self) -> float:
        return float(self.egos.speeds[0])

    @property
    def metrics(self) -> EpisodeMetrics:
        """Ego 0's §VI-B metrics (``self.egos.metrics[i]`` for ego i)."""
        return self.egos.metrics[0]

    # ------------------------------------------------------------------ dynamics
    def _advance_agents(self, brake: np.ndarray, ped_brake: np.ndarray) -> None:
        n = len(self.states)
        idx = np.minimum(self.plan_index, self.plans.shape[1] - 1)
        u = self.plans[np.arange(n), idx]
        u[brake] = 0.0
        self.states = step_vehicle(self.states, u, self.dt)
        self.plan_index = self.plan_index + (~brake)
        if len(self.ped_pos):
            pidx = np.minimum(self.ped_index, self.ped_plans.shape[1] - 1)
            pu = self.ped_plans[np.arange(len(self.ped_pos)), pidx]
            pu[ped_brake, 0] = 0.0
            self.ped_prev = self.ped_pos.copy()
            self.ped_pos = step_pedestrian(self.ped_pos, pu, self.dt)
            self.ped_index = self.ped_index + (~ped_brake)

    def _reactive_brakes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """§III-B for every ego in the lot (K > 1: a departure, :mod:`.egos`): (vehicles that brake, pedestrians that
        stop, (K,) the number of agents braking for each ego)."""
        brake, ped_brake = np.zeros(len(self.states), dtype=bool), np.zeros(len(self.ped_pos), dtype=bool)
        counts = np.zeros(self.egos.count, dtype=np.int64)
        self.braking_for = np.zeros((len(self.states), self.egos.count), dtype=bool)  # (agent, ego): who for whom
        for j in np.nonzero(self.egos.present)[0]:
            b, pb = self._brakes_for(self.egos.poses[j])
            counts[j] = int((b & self.is_dynamic).sum()) + int(pb.sum())
            self.braking_for[:, j] = b
            brake |= b
            ped_brake |= pb
        return brake, ped_brake, counts

    def _brakes_for(self, ego: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """§III-B: agent A brakes iff A_tau meets V_0,t for some tau = t + dt, ..., t + n_pass,A dt."""
        n = len(self.states)
        ego_fp = rect_corners(ego, self.scenario.ego.length, self.scenario.ego.width)
        brake = np.zeros(n, dtype=bool)
        cand = np.nonzero(self.passiveness > 0)[0]
        if len(cand):  # agents that cannot reach the ego within their n_pass steps cannot brake
            gap = np.hypot(self.states[cand, 0] - ego[0], self.states[cand, 1] - ego[1])
            cand = cand[gap <= self._brake_reach[cand]]
        max_pass = int(self.passiveness[cand].max(initial=0))
        if max_pass > 0 and len(cand):
            ahead = plan_lookahead(self.states[cand], self.plans, cand, self.plan_index[cand], max_pass,
                                   step_vehicle, self.dt)
            fp = rect_corners(ahead, self.vehicle_dims[cand, 0, None], self.vehicle_dims[cand, 1, None])
            hit = rects_overlap(fp, ego_fp[None, None]) & (np.arange(max_pass)[None] < self.passiveness[cand, None])
            brake[cand[hit.any(axis=1)]] = True
        p = len(self.ped_pos)
        ped_brake = np.zeros(p, dtype=bool)
        max_pp = int(self.ped_pass.max(initial=0))
        if max_pp > 0 and p:
            pos = plan_lookahead(self.ped_pos, self.ped_plans, np.arange(p), self.ped_index, max_pp, step_pedestrian,
                                 self.dt)
            hit = disc_rect_overlap(pos, self.ped_radii[:, None], ego_fp[None, None])
            ped_brake = (hit & (np.arange(max_pp)[None] < self.ped_pass[:, None])).any(axis=1)
        return brake, ped_brake

    def clip_command(self, v: float, omega: float) -> tuple[float, float]:
        """The ego is a car: |v| <= v_max and |omega| <= |v| / R_min (eq. 1 with a curvature bound)."""
        vmax = self.config.ego_max_speed
        v = float(np.clip(v, -vmax, vmax))
        wmax = abs(v) * self.scenario.ego.max_curvature
        return v, float(np.clip(omega, -wmax, wmax))

    def step(self, v: float, omega: float) -> str:
        """Advance one dt with ego command (v, omega); returns the episode status. One ego (K > 1: :meth:`step_all`)."""
        if self.egos.count != 1:
            raise ValueError(f"World.step drives one ego; this world has {self.egos.count}: use step_all")
        return self.step_all([(v, omega)])

    def step_all(self, commands) -> str:
        """Advance one dt with one command (v, omega) per ego (those of egos not driving are ignored); returns the
        episode status (running while any ego runs)."""
        if self.status != RUNNING:
            return self.status
        eg = self.egos
        if len(commands) != eg.count:
            raise ValueError(f"step_all needs {eg.count} commands (one per ego), got {len(commands)}")
        driving = eg.driving
        cmds = np.zeros((eg.count, 2))
        for i, (v, omega) in enumerate(commands):
            if not (math.isfinite(v) and math.isfinite(omega)):
                raise ValueError(f"ego command must be finite, got v={v}, omega={omega}" + (f" (ego {i})" if i else ""))
            if driving[i]:
                cmds[i] = self.clip_command(v, omega)
        brake, ped_brake, counts = self._reactive_brakes()
        self.braking = brake
        self.ped_braking = ped_brake
        for i in np.nonzero(driving)[0]:
            eg.metrics[i].interrupted_agent_steps += int(counts[i])
            eg.metrics[i].interrupted_steps += int(counts[i] > 0)
        if self.config.agents_yield:
            v_yield, p_yield = agents_yield(self)
            self.yielding, self.ped_yielding = v_yield & ~brake, p_yield & ~ped_brake
            brake, ped_brake = brake | v_yield, ped_brake | p_yield
        self._advance_agents(brake, ped_brake)
        self.history = np.concatenate([self.history[:, 1:], self.states[:, None]], axis=1)
        for i in range(eg.count):
            if driving[i]:
                eg.poses[i] = step_vehicle(eg.poses[i], cmds[i], self.dt)
            eg.speeds[i] = cmds[i, 0]
        eg.push_history()
        self.step_index += 1
        self.log_ego.append(self.ego.copy())
        self.log_egos.append(eg.poses.copy())
        self.log_vehicles.append(self.states.copy())
        self.log_braking.append(self.braking.copy())
        self.log_commands.append(cmds[0].copy() if eg.count == 1 else cmds)
        self._enter_due_ego()
        self._check_events()
        return self.status

    def _enter_due_ego(self) -> None:
        """The first ego whose entry time has come enters at the gate, if no vehicle or ego stands on it or within
        ``entry_clearance`` of it (a car never appears touching the one ahead)."""
        eg = self.egos
        for i in eg.waiting():
            if self.step_index < eg.due_step[i]:
                return
            margin = 2.0 * self.config.entry_clearance
            gate = rect_corners(eg.starts[i], eg.length + margin, eg.width + margin)[None]
            blockers = [self.vehicle_corners()]
            if eg.present.any():
                blockers.append(eg.corners(np.nonzero(eg.present)[0]))
            if rects_overlap(np.concatenate(blockers), gate).any():
                return  # the gate is taken: it waits (its parking time starts when it enters)
            eg.enter(i, self.step_index)
            return

    # ------------------------------------------------------------------ events and metrics
    def vehicle_corners(self) -> np.ndarray:
        return rect_corners(self.states, self.vehicle_dims[:, 0], self.vehicle_dims[:, 1])

    def ego_corners(self, i: int = 0) -> np.ndarray:
        return rect_corners(self.egos.poses[i], self.scenario.ego.length, self.scenario.ego.width)

    def _with_egos(self, corners: np.ndarray, ids: np.ndarray, others: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The agents' corners and ids with those of the egos ``others`` appended (as observed vehicles)."""
        if not len(others):
            return corners, ids
        return (np.concatenate([corners, self.egos.corners(others)]),
                np.concatenate([ids, EGO_ID_BASE + others.astype(np.int64)]))

    def _check_events(self) -> None:
        eg = self.egos
        agents = self.vehicle_corners()
        for i in np.nonzero(eg.driving)[0]:
            corners, ids = self._with_egos(agents, self.vehicle_ids, eg.others(i))
            status, who, parked = step_event(self.lot, self.ego_corners(i), corners, ids, self.ped_pos,
                                             self.ped_radii, self.ped_ids)
            m = eg.metrics[i]
            eg.status[i] = apply_event(m, status, eg.ego_name(who), parked, self.step_index, self.dt,
                                       self.config.t_final, self.target_spot[self.is_dynamic],
                                       ego_moved=self.step_index > 0 and eg.speeds[i] != 0.0)
            if m.success and eg.entered_step[i] > 0:  # parking time from its entry (K > 1)
                m.parking_time = (self.step_index - int(eg.entered_step[i])) * self.dt
        self.status = self._episode_status()

    def _episode_status(self) -> str:
        """K = 1: the ego's. K > 1: running while any ego runs or may still enter; then success if every ego
        parked, collision if any collided, else timeout (an ego that never entered times out)."""
        eg = self.egos
        if eg.n_auto == 1:  # one ego (and any driven cars, which the episode never waits for)
            return eg.status[0]
        if self.step_index * self.dt >= self.config.t_final - 1e-9:
            for i in eg.waiting():
                eg.status[i] = TIMEOUT
                eg.metrics[i].steps = self.step_index
        auto = eg.status[:eg.n_auto]
        if any(s == RUNNING for s in auto):
            return RUNNING
        if all(s == SUCCESS for s in auto):
            return SUCCESS
        return COLLISION if COLLISION in auto else TIMEOUT

    @property
    def done(self) -> bool:
        return self.status != RUNNING

    # ------------------------------------------------------------------ observation (§III-A)
    def occupancy(self) -> tuple[np.ndarray, np.ndarray]:
        """(spot_occupied, vehicle_spot) of the current step (:func:`classify_world`), computed once per step."""
        if self._occupancy_step != self.step_index:
            self._occupancy = self._tracker.classify(self.vehicle_corners())
            self._occupancy_step = self.step_index
        return self._occupancy

    def occupancy_with(self, egos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(spot_occupied, vehicle_spot) of the agents and then the egos ``egos`` (rows in that order): what
        :func:`classify_world` gives for their corners stacked, with the agents' part taken from
        :meth:`occupancy`. Each vehicle's spot depends on that vehicle alone, so only the egos are classified."""
        occupied, vehicle_spot = self.occupancy()
        if not len(egos):
            return occupied, vehicle_spot
        ego_occupied, ego_spot = classify_world(self.lot, self.egos.corners(egos))
        return occupied | ego_occupied, np.concatenate([vehicle_spot, ego_spot])

    def observe(self, i: int = 0) -> Observation:
        """What ego ``i`` senses now: rays stop at the lot boundary, other vehicles (the other egos among them) or dQ
        (no ground truth). :attr:`last_scan` keeps this call's :class:`~avp_sensing.observation.RayScan`."""
        eg = self.egos
        if not eg.present[i]:
            raise ValueError(f"ego {i} has not entered the lot yet")
        others = eg.others(i)
        corners, _ = self._with_egos(self.vehicle_corners(), self.vehicle_ids, others)
        scan = self.caster.cast(eg.poses[i], corners, self.ped_pos, self.ped_radii)
        self.last_scan = scan  # what the rays touched, for a sensing model (avp_sensing.noisy); not observed
        occupied, vehicle_spot = self.occupancy_with(others)
        seen_spots = scan.seen_spots
        vac = self.lot.spot_ids[seen_spots & ~occupied]
        occ = self.lot.spot_ids[seen_spots & occupied]
        n_agents = len(self.states)
        vehicles = tuple(
            ObservedVehicle(
                id=int(self.vehicle_ids[i]),
                length=float(self.vehicle_dims[i, 0]),
                width=float(self.vehicle_dims[i, 1]),
                is_static=bool(vehicle_spot[i] >= 0),
                history=self.history[i].copy(),
            )
            for i in np.nonzero(scan.seen_vehicles[:n_agents])[0]
        ) + tuple(
            ObservedVehicle(id=EGO_ID_BASE + int(j), length=eg.length, width=eg.width,
                            is_static=bool(vehicle_spot[n_agents + r] >= 0), history=eg.history[j].copy())
            for r, j in enumerate(others) if scan.seen_vehicles[n_agents + r]
        )
        peds = tuple(
            ObservedPedestrian(int(self.ped_ids[i]), float(self.ped_radii[i]), self.ped_pos[i].copy(),
                               self.ped_prev[i].copy())
            for i in np.nonzero(scan.seen_pedestrians)[0]
        )
        n_ray = self.config.sensor.n_ray
        return Observation(
            step=self.step_index,
            dt=self.dt,
            ego_pose=eg.poses[i].copy(),
            ego_length=self.scenario.ego.length,
            ego_width=self.scenario.ego.width,
            ego_speed=float(eg.speeds[i]),
            vacant_spot_ids=vac.astype(np.int64),
            occupied_spot_ids=occ.astype(np.int64),
            vehicles=vehicles,
            pedestrians=peds,
            ray_angle_min=0.0,
            ray_angle_increment=2.0 * math.pi / n_ray,
            ray_ranges=scan.ranges.astype(np.float32),
        )

    def ground_truth(self) -> dict:
        """Everything, for metrics and rendering only (the debug topic)."""
        return {
            "step": self.step_index,
            "ego": self.ego.copy(),
            "vehicle_ids": self.vehicle_ids,
            "vehicles": self.states.copy(),
            "dims": self.vehicle_dims,
            "braking": self.braking.copy(),
            "target_spot": self.target_spot,
            "is_dynamic": self.is_dynamic,
            "pedestrians": self.ped_pos.copy(),
            "egos": self.egos.poses.copy(),
            "egos_present": self.egos.present.copy(),
        }

"""Seeded parking-lot traffic for the intent model's training data (docs/intent_model.md), as plans of eq. (1).

Every car is a :class:`~avp_scenario.scenario.VehicleAgent` (initial state + control plan), so the existing
:class:`~avp_sim.core.world.World` simulates it (reactive braking for the ego included, §III-B). Kinds:

* **parkers** wait 12 m outside the entrance (outside the lot: rays stop at its boundary, §III-A, so the
  ego never sees them), drive in at 2 m/s and then cruise (speed ~ U[2, 4] m/s; ParkSim cruises at 5 m/s)
  along the right-hand lanes (:mod:`.lanes`). Most are **goal-directed**, as ParkSim's task-based drivers
  (reference sheet §3.3): at the entrance a driver picks a spot among those free at its estimated arrival,
  with weight exp(-d / L) over the route length d (L ~ U[15, 60] m per driver: drivers prefer near spots,
  x 0.7 for spots across the aisle), and drives the shortest lane route to it. A share ``p_explore`` = 0.15
  **explore** instead: at every node they pick a next lane (no U-turns, no dead ends), less likely one driven
  before, more likely one along which spots are free; passing a free, unreserved spot they take it with
  probability 1 - (1 - p) exp(-tau / 60 s) (p ~ U[0.3, 0.85] per driver, tau: time spent searching; x 0.7
  across the aisle). A taken spot is parked in with one of ParkSim's 8 maneuvers
  (:mod:`avp_scenario.maneuvers`): the side (near/far) follows from the spot's side of the lane, stop before
  (80 %: ParkSim overshoots only near the ends of rows) or after the spot, head-in or tail-in (50 %); the
  driver slows to U[0.8, 1.5] m/s (ParkSim: v_end = 1 m/s) over the last U[6, 12] m, stops at the
  maneuver's start pose on its lane, waits U[0, 1.5] s and runs the maneuver. Label: that spot. An explorer
  who has searched U[150, 400] m without taking a spot drives to the exit ("wanderer", label none).
* **leavers** sit in an occupied spot, unpark at a random time (a maneuver played backwards, ParkSim's
  unparking) and drive the shortest way out (label none).
* the other occupied spots hold parked cars (random facing, as the §VI-A generator).

Occupancy ~ U[0.5, 0.95]; arrivals and departures are Poisson processes (mean gaps drawn per lot). Traffic
starts ``t_pre`` = 40 s before the episode's history, so cars are already on their way at t = 0. A new plan
that comes within 0.3 m of an accepted one (0.02 m when both stand still) at the same step is re-drawn
(agents do not react to each other in the World, §III-B), then delayed, then dropped. Labels come from the
plans: the spot each car actually ends in.

The observer (ego) drives a random tour of the lanes (:func:`plan_ego`); the episode runner
(:mod:`.dataset`) lets it hold while its next footprints would meet another car.
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import shapely

from avp_scenario.scenario import Scenario, VehicleAgent
from avp_traffic.agents import AgentPlannersMixin
from avp_traffic.lanes import LaneGraph, Path, follow, rollout
from avp_traffic.types import (  # noqa: F401 - re-exported: the generator's API
    AGENT_ID0,
    LEAVE,
    PARK,
    WANDER,
    AgentPlan,
    ManeuverLibrary,
    Traffic,
    TrafficParams,
    moving_flags,
    slow_tail,
)
from avp_world.geometry import polygon_contains_points, rect_corners, rect_inside_rect, rects_overlap, wrap_angle
from avp_world.lot import LotMap
from avp_world.lot_scenario import spot_aisles
from avp_world.vehicle import VehicleSpec


class TrafficGenerator(AgentPlannersMixin):
    """Builds :class:`Traffic` episodes on one lot (module docstring)."""

    def __init__(self, lot: LotMap, params: TrafficParams = TrafficParams(), vehicle: VehicleSpec = VehicleSpec()):
        self.lot, self.p, self.vehicle = lot, params, vehicle
        self.spot_road = spot_aisles(lot)
        self.graph = LaneGraph.build(lot, self.spot_road)
        self.lib = ManeuverLibrary(lot, self.graph, self.spot_road, vehicle)
        self.n_total = int(round((params.t_pre + params.t_hist + params.t_final) / params.dt))
        self.k_hist = int(round(params.t_pre / params.dt))  # index of t = -t_hist
        grown = shapely.Polygon(lot.boundary).buffer(2.5, join_style="mitre")
        self.grown = np.asarray(grown.exterior.coords)[:-1]
        self.walk_lanes = {ln.id for ln in self.graph.lanes if ln.road >= 0 and ln.v not in self.graph.dead_ends}
        self.why: Counter = Counter()  # why plans were discarded (statistics)
        self.spot_lanes: dict[int, list[tuple[int, float, str]]] = {}
        for lane, items in self.graph.spot_lanes.items():
            for row, t, side in items:
                self.spot_lanes.setdefault(row, []).append((lane, t, side))
        self.entry_routes: dict[int, list[int]] = {}  # lane with spots -> shortest lane route from the entrance
        self.entry_dist: dict[int, float] = {}  # ... and its length up to that lane's start
        for lane in self.graph.spot_lanes:
            try:
                seq = self.graph.shortest(self.graph.entry, lane)
            except ValueError:
                continue
            self.entry_routes[lane] = seq
            self.entry_dist[lane] = float(sum(self.graph.lanes[ln].length for ln in seq[:-1]))

    # ------------------------------------------------------------------ helpers
    def _time(self, k: int) -> float:
        return (k - self.k_hist) * self.p.dt - self.p.t_hist

    def _pad(self, k0: int, start: np.ndarray, controls: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Full-timeline controls and states: hold ``start`` until index k0, then ``controls``, then hold."""
        n = self.n_total
        u = np.zeros((n, 2))
        m = max(0, min(len(controls), n - k0))
        if k0 < n:
            u[k0:k0 + m] = controls[:m]
        return u, rollout(start, u, self.p.dt)

    def _inside(self, states: np.ndarray) -> np.ndarray:
        return polygon_contains_points(self.grown, states[:, :2])

    def _conflict(self, plan: AgentPlan, accepted: list[AgentPlan], inside: np.ndarray,
                  accepted_inside: list[np.ndarray]) -> bool:
        length, width = self.vehicle.length, self.vehicle.width
        reach = math.hypot(length, width) + self.p.moving_margin + 0.01
        for other, o_in in zip(accepted, accepted_inside, strict=True):
            d = np.hypot(*(plan.states[:, :2] - other.states[:, :2]).T)
            idx = np.nonzero((d < reach) & inside & o_in)[0]
            if len(idx) == 0:
                continue
            a = rect_corners(plan.states[idx], length, width)
            b = rect_corners(other.states[idx], length, width)
            moving = plan.moving[idx] | other.moving[idx]
            hit = np.where(moving, rects_overlap(a, b, self.p.moving_margin), rects_overlap(a, b, self.p.still_margin))
            if hit.any():
                return True
        return False

    def _available(self, row: int, t: float, free_from: np.ndarray, reserved: np.ndarray) -> bool:
        return not reserved[row] and free_from[row] <= t

    # ------------------------------------------------------------------ parkers and wanderers
    def plan_ego(self, rng: np.random.Generator, accepted: list[AgentPlan], start_pose=None
                 ) -> tuple[np.ndarray, np.ndarray]:
        """The observer's plan (controls, states from t = 0). From ``start_pose`` (merging into the lane it lies
        beside): a random tour of the lanes at U[1.5, 3] m/s. Otherwise one of three modes, so that it meets
        the traffic in a large lot: *follow* (40 %) — it starts 3-6 s behind a parker on that car's path,
        replays its driving controls up to the parker's maneuver start (holding behind it while it parks),
        then tours on; *meet* (40 %) — it starts on a lane 10-40 m from the spot a parker will take in the
        first 40 s; *random* — anywhere; the last two clear of the traffic at t = 0, then a random tour."""
        p = self.p
        v = float(rng.uniform(*p.ego_speed))
        k_zero = self.k_hist + int(round(p.t_hist / p.dt))
        if start_pose is not None:
            lane, t0, pre = self._merge(np.asarray(start_pose, float))
            return self._tour(rng, np.asarray(start_pose, float), lane, t0, v, pre)
        mode = rng.choice(3, p=[0.4, 0.4, 0.2])
        parkers = [a for a in accepted if a.kind == PARK and a.drive_end > k_zero]
        if mode == 0:
            k_back = int(round(rng.uniform(3.0, 6.0) / p.dt))
            kb = k_zero - k_back
            ok = [a for a in parkers
                  if a.drive_end - k_zero > 30 and a.moving[kb] and self._inside(a.states[kb:kb + 1])[0]]
            for _ in range(3 if ok else 0):
                a = ok[int(rng.integers(len(ok)))]
                u0 = a.controls[k_zero - k_back:a.drive_end]
                x0 = rollout(a.states[k_zero - k_back], u0, p.dt)
                try:
                    u1, x1 = self._tour(rng, x0[-1], a.end_lane, a.end_t, v)
                except ValueError:  # the stop lies beyond the next turn's start: no tour from there
                    continue
                return np.concatenate([u0, u1]), np.concatenate([x0, x1[1:]])
        spots = np.array([self.lot.spot_poses[a.spot_row, :2] for a in parkers
                          if a.drive_end < k_zero + int(round(40.0 / p.dt))]).reshape(-1, 2)
        others = np.array([a.states[k_zero] for a in accepted]).reshape(-1, 3)
        walk = sorted(self.walk_lanes)
        for attempt in range(400):
            lane = int(rng.choice(walk))
            t0 = float(rng.uniform(3.0, max(3.5, self.graph.lanes[lane].length - 3.0)))
            pt = self.graph.lanes[lane].point(t0)
            start = np.array([pt[0], pt[1], self.graph.lanes[lane].heading])
            if mode == 1 and len(spots) and attempt < 300:
                gap = np.hypot(*(spots - start[:2]).T).min()
                if not 10.0 <= gap <= 40.0:
                    continue
            fp = rect_corners(start, self.vehicle.length, self.vehicle.width)
            if len(others) and rects_overlap(rect_corners(others, self.vehicle.length, self.vehicle.width),
                                             fp[None], p.ego_clearance).any():
                continue
            try:
                return self._tour(rng, start, lane, t0, v)
            except ValueError:
                continue
        raise RuntimeError("no start for the observer")

    def _tour(self, rng: np.random.Generator, state: np.ndarray, lane: int, t0: float, v: float,
              pre: list | None = None) -> tuple[np.ndarray, np.ndarray]:
        """A random walk over the lanes from ``state`` (on ``lane`` at t0, after the optional ``pre`` pieces),
        long enough for the episode, driven by :func:`follow`. ValueError where the first turn starts behind t0."""
        p, g = self.p, self.graph
        lanes = [lane]
        total = g.lanes[lane].length - t0
        visits = {lane: 1}
        while total < v * p.t_final + 30.0:
            opts = [n for n in g.nexts[lanes[-1]] if n in self.walk_lanes]
            w = np.array([0.2 ** visits.get(n, 0) for n in opts])
            nxt = int(opts[int(rng.choice(len(opts), p=w / w.sum()))])
            lanes.append(nxt)
            visits[nxt] = visits.get(nxt, 0) + 1
            total += g.lanes[nxt].length
        _, pieces = g.route_pieces(lanes, t0, g.lanes[lanes[-1]].length / 2.0, v)
        pre = [(ln, k, min(c, v)) for ln, k, c in (pre or [])]
        return follow(Path.build(state, pre + pieces), state, p.dt, self.vehicle)

    def _merge(self, pose: np.ndarray) -> tuple[int, float, list]:
        """Lane beside ``pose`` (same heading, lateral offset <= 2.5 m) and an S-curve (two opposite arcs of
        6 m radius) onto it: (lane, lane coordinate where the S-curve ends, pieces)."""
        g = self.graph
        for ln in g.lanes:
            if ln.road < 0 or abs(wrap_angle(pose[2] - ln.heading)) > 1e-3:
                continue
            t = float((pose[:2] - ln.a) @ ln.d)
            lat = float((pose[:2] - ln.a) @ np.array([-ln.d[1], ln.d[0]]))
            if abs(lat) <= 2.5 and -ln.width / 2 <= t <= ln.length - 8.0:
                if abs(lat) < 1e-6:
                    return ln.id, t, []
                r = 6.0
                phi = math.acos(1.0 - abs(lat) / (2.0 * r))
                k = -math.copysign(1.0 / r, lat)  # pose left of the lane (lat > 0): turn right first
                return ln.id, t + 2.0 * r * math.sin(phi), [(r * phi, k, 9.9), (r * phi, -k, 9.9)]
        raise ValueError(f"no lane beside the pose {pose.tolist()}")

    # ------------------------------------------------------------------ episode
    def generate(self, seed: int, ego_start=None, ego_tour: bool = True) -> Traffic:
        """One seeded episode (same seed => same traffic). ``ego_tour`` False: the ego stands at ``ego_start``
        (its plan is someone else's business: the busy scenario family, :mod:`.busy`)."""
        p = self.p
        rng = np.random.default_rng(int(seed))
        n_s = self.lot.n_spots
        occ = rng.random(n_s) < rng.uniform(*p.occupancy)
        free_from = np.where(occ, np.inf, -np.inf)
        reserved = np.zeros(n_s, dtype=bool)
        accepted: list[AgentPlan] = []
        inside: list[np.ndarray] = []
        stats = {"rejected": 0, "dropped": 0}

        def accept(plan: AgentPlan) -> None:
            accepted.append(plan)
            inside.append(self._inside(plan.states))

        t_end = p.t_final - 10.0
        # leavers: departures of parked cars
        gap = float(rng.uniform(*p.departure_gap))
        t = self._time(0) + float(rng.exponential(gap))
        while t < t_end:
            rows = np.nonzero(occ & ~reserved & np.isinf(free_from))[0]
            if len(rows) == 0:
                break
            row = int(rng.choice(rows))
            k0 = int(round((t - self._time(0)) / p.dt))
            plan = self._leaver(rng, row, k0)
            if plan is not None and not self._conflict(plan, accepted, self._inside(plan.states), inside):
                accept(plan)
                clear = int(np.nonzero(plan.moving)[0].min()) + 1
                out = np.nonzero(~rects_overlap(rect_corners(plan.states[clear:], self.vehicle.length,
                                                             self.vehicle.width),
                                                self.lot.spot_corners[row][None]))[0]
                free_from[row] = self._time(clear + (int(out[0]) if len(out) else 0)) + 2.0
            else:
                stats["rejected"] += 1
            t += float(rng.exponential(gap))
        # parkers and wanderers, in order of their start from the queue
        gap = float(rng.uniform(*p.arrival_gap))
        t = self._time(0) + float(rng.exponential(gap))
        while t < t_end:
            k0 = int(round((t - self._time(0)) / p.dt))
            done = False
            for delay in range(p.delays + 1):
                kd = k0 + delay * int(round(p.delay / p.dt))
                for _ in range(p.tries):
                    plan = self._parker(rng, kd, free_from, reserved)
                    if plan is None:
                        continue
                    plan_in = self._inside(plan.states)
                    if self._conflict(plan, accepted, plan_in, inside):
                        stats["rejected"] += 1
                        continue
                    accept(plan)
                    if plan.kind == PARK:
                        reserved[plan.spot_row] = True
                    done = True
                    break
                if done:
                    break
            if not done:
                stats["dropped"] += 1
            t += max(p.min_arrival_gap, float(rng.exponential(gap)))

        if ego_tour or ego_start is None:
            ego_u, ego_x = self.plan_ego(rng, accepted, ego_start)
        else:
            ego_u, ego_x = np.zeros((0, 2)), np.asarray(ego_start, dtype=float).reshape(1, 3)
        return self._assemble(seed, rng, occ, accepted, ego_u, ego_x, stats)

    def _assemble(self, seed: int, rng: np.random.Generator, occ: np.ndarray, accepted: list[AgentPlan],
                  ego_u: np.ndarray, ego_x: np.ndarray, stats: dict) -> Traffic:
        p, kh = self.p, self.k_hist
        vehicles: list[VehicleAgent] = []
        labels: dict[int, int] = {}
        kinds: dict[int, str] = {}
        plans: dict[int, AgentPlan] = {}
        leaving_rows = {a.spot_row for a in accepted if a.kind == LEAVE}
        for row in np.nonzero(occ)[0]:
            if int(row) in leaving_rows:
                continue
            s = self.lot.spots[int(row)]
            heading = s.heading + (math.pi if rng.random() < 0.5 else 0.0)
            pose = np.array([s.x, s.y, math.atan2(math.sin(heading), math.cos(heading))])
            vehicles.append(VehicleAgent(id=int(row), length=p.parked_length, width=p.parked_width,
                                         initial_state=pose, controls=np.zeros((0, 2)), parked=True))
        n_parked = len(vehicles)
        for j, a in enumerate(accepted):
            later = a.moving[kh:]
            if not later.any():
                fp = rect_corners(a.states[kh], self.vehicle.length, self.vehicle.width)
                if not polygon_contains_points(self.grown, a.states[kh:kh + 1, :2])[0]:
                    continue  # left the lot before the episode
                if a.kind == PARK and rect_inside_rect(fp[None], self.lot.spot_corners[a.spot_row][None])[0]:
                    vehicles.append(VehicleAgent(id=AGENT_ID0 + j, length=self.vehicle.length,
                                                 width=self.vehicle.width, initial_state=a.states[kh].copy(),
                                                 controls=np.zeros((0, 2)), parked=True))
                    n_parked += 1
                    continue
            vid = AGENT_ID0 + j
            label = int(self.lot.spot_ids[a.spot_row]) if a.kind == PARK else -1
            vehicles.append(VehicleAgent(
                id=vid, length=self.vehicle.length, width=self.vehicle.width, initial_state=a.states[kh].copy(),
                controls=a.controls[kh:].copy(), passiveness=int(rng.integers(p.passiveness[0], p.passiveness[1] + 1)),
                target_spot_id=label, maneuver=a.maneuver))
            labels[vid] = label
            kinds[vid] = a.kind
            plans[vid] = a
        stats.update({k: sum(a.kind == k for a in accepted) for k in (PARK, LEAVE, WANDER)})
        scenario = Scenario(seed=int(seed), reactive=True, ego_start=ego_x[0].copy(), ego=self.vehicle,
                            vehicles=tuple(vehicles), dt=p.dt, t_hist=p.t_hist)
        return Traffic(scenario, labels, kinds, ego_u, ego_x, n_parked, stats, plans)

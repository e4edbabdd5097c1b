"""The ego's decision of paper §V-D ("Final Trajectory Planning"): park, else explore, else idle (ROS-free).

At each step t, :meth:`EgoPlanner.decide` receives the observation (§III-A), the belief map b_t (§V-B; or
``None``) and the predicted trajectories (§V-C), and returns a :class:`Decision` with the command u_0,t.

**Beliefs.** With ``beliefs=None`` the planner keeps "beliefs from observation only" (the first update of
§V-B without the intention model): b = 0.5 initially; observed vacant -> 0, observed occupied -> 1,
otherwise kept.

**Static world** (:mod:`~avp_planner.core.collision`): lot boundary, spots with b >= β as full spot
rectangles, observed static vehicles. **Dynamic obstacles**: the given predictions; an observed dynamic
vehicle or pedestrian without any prediction gets a constant-velocity one (``fallback_prediction``; §V-C uses
constant velocity for pedestrians), so that the planner stays safe when run without a prediction module.

**Parking (§V-D-1).** Candidates I_can,0 = {i in I_vac,t : b_t,i <= δ}. Goals: the ego centred in the spot with
the spot heading or its opposite (both seeds of one Hybrid A* search). Candidates are searched in order of
a lower bound of c_park (from the exact obstacle-free Reeds-Shepp length and the 2-D obstacle-aware
distance), and the loop stops when the next lower bound is not below the best feasible cost found
(branch and bound: the result is the one of planning every candidate, at a fraction of the cost). A path is
time-indexed with its speed profile (:mod:`~avp_planner.core.control`) and kept if its footprints avoid
every predicted agent at the same time index; if not, starting it after a wait of up to ``max_wait`` is
tried (wait-and-go, as in Nawaz et al.). The feasible plan of lowest c_park wins:

    c_park = w_length L + w_reverse L_rev + w_switch n_switch + w_time (T + t_wait)
             + w_static sum_k exp(-3 d_k) |Δs_k| + w_dynamic sum_k sum_agents exp(-2 g_k) Δt

after Nawaz's evaluate_path (length, reversing, switch-backs, time incl. waiting, and exponential proximity to
static obstacles (d_k: footprint clearance from the distance transform) and to predicted agents (g_k: gap
of the footprints)). The chosen path is tracked into eq. (1) controls, verified (every state free with
``verify_margin``, no predicted agent) and executed step by step across calls. It is **replanned** when the
ego is not where the plan expects it, when the rest of the plan meets a static obstacle of the current
step (newly observed occupied spot / static vehicle), when it meets a predicted agent, or when it is
exhausted.

**Exploration (§V-D-2).** Exploration points: the crossings of the road centre lines with the boundary of
the sensing disc of radius ``sensing_radius`` around the ego, heading along the road away from the ego; the
goal is moved ``explore_lane_offset`` to the right of that heading (drive on the right lane; 0 = the paper
literally) and, if in collision, slid back along the road. Points in front of the ego
([cos θ, sin θ] (p - p_ego) >= 0) are planned first (lowest c, same Hybrid A*); points behind only if no front
point has a feasible plan, and, when the front points are blocked by predicted agents only (not by static
obstacles), only after that has lasted ``EXPLORE_BACK_AFTER`` = 3 s ("only if the road ahead of it stays
blocked for the foreseeable future"). A front point that can only be reached by a path longer than
``explore_max_length`` (e.g. all the way round a block because the road ahead is blocked) counts as
blocked. While exploring, parking is re-tried every step in which the candidate set, the static world or
the ego's cell changed (or every ``park_retry_steps`` steps); an exploration plan is followed until less
than ``explore_replan_distance`` of it is left.

**Idling (§V-D-3).** Otherwise u = 0. If all plans were blocked only by predicted agents, the searches are
repeated once (small budget) with the current footprints of the agents that stand still as static
obstacles (``dynamic_as_static_fallback``), which lets the ego drive around a stopped car. Two safety
additions to the paper's rule: an agent that is already closer than the margin to the ego (a reactive car
that stopped next to it) only has to keep its
current gap (:class:`~avp_planner.core.collision.DynamicObstacles`), so the ego is not frozen next to it;
and if standing still is itself predicted to be hit (``evasive``), the ego drives the candidate that is hit
latest or never: a blocked plan of this step or a short escape arc (forward/reverse, 2-8 m).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from avp_planner.core.collision import DynamicObstacles, StaticWorld
from avp_planner.core.control import Trajectory, reference_trajectory, track
from avp_planner.core.hybrid_astar import EgoHeuristic, HybridAStar, PlanResult
from avp_planner.core.paths import Path, wrap
from avp_planner.core.rs_scalar import rs_shortest
from avp_planner.core.settings import PlannerSettings
from avp_world.geometry import rect_corners, rect_inside_rect
from avp_world.kinematics import step_vehicle
from avp_world.lot import LotMap
from avp_world.types import Observation, PredictedTrajectory

PARK, EXPLORE, IDLE = "park", "explore", "idle"
STILL_SPEED = 0.3  # m/s: an agent slower than this counts as standing still (detour instead of waiting)
EXPLORE_BACK_AFTER = 3.0  # s the road ahead must stay blocked by agents only before turning back (§V-D-2)
WORLD_CACHE_SIZE = 8  # static worlds kept (see EgoPlanner._static_world)
#: failed searches remembered by (static world, ego pose, goals, limits): the same search fails the same way, so a
#: stand-still ego in an unchanged scene does not search again for seconds per step (iteration-limited failures
#: only; one ended by the wall-clock cap is not repeatable)
FAILED_SEARCH_CACHE = 512
CONTAINED_MARGIN = 0.3  # m: a static vehicle this far inside an occupied spot is left out of the raster


@dataclass
class Decision:
    """What the planner decided at one step.

    mode: 'park' | 'explore' | 'idle'; spot_id: the target spot (-1 unless parking); goal: (3,) goal pose
    (None when idle); poses: (K, 3) the planned states from now on (poses[0] = current pose); controls:
    (K - 1, 2) the remaining controls; command: (v, ω) for this step; timings: seconds
    (``spot_selection_time``: candidate selection, ordering, pricing and prediction checks;
    ``path_planning_time``: Hybrid A* searches and tracking; ``total``); n_candidates: |I_can,0|;
    reason: why this mode (or why a plan was dropped); cost: c of the plan; stats: details.
    """

    mode: str
    spot_id: int = -1
    goal: np.ndarray | None = None
    poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    controls: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    command: tuple[float, float] = (0.0, 0.0)
    timings: dict = field(default_factory=dict)
    n_candidates: int = 0
    reason: str = ""
    cost: float = math.nan
    replanned: bool = False
    stats: dict = field(default_factory=dict)


def priority_from_probabilities(spot_ids: Sequence[int], probabilities: Sequence[float]) -> np.ndarray:
    """Spot ids in decreasing probability, ties smaller id first: the ``spot_priority`` of the "Implicit" method
    (§VI-B-3) from the ego's own intention eta_0,i (avp_perception.core.implicit, the ``ego_intention`` topic)."""
    ids = np.asarray(spot_ids, dtype=np.int64).reshape(-1)
    p = np.asarray(probabilities, dtype=float).reshape(-1)
    if len(ids) != len(p):
        raise ValueError(f"{len(ids)} spot ids but {len(p)} probabilities")
    return ids[np.lexsort((ids, -p))]


@dataclass
class _Plan:
    mode: str
    spot_id: int
    goal: np.ndarray
    traj: Trajectory
    cost: float
    margins: np.ndarray  # static clearance each state keeps (0 near the start, verify_margin after)
    index: int = 0  # next control to send
    path_length: float = 0.0
    note: str = ""


@dataclass
class _Candidate:
    """One evaluated plan (before tracking)."""

    mode: str
    spot_id: int
    goal: np.ndarray
    path: Path
    cost: float
    wait_steps: int
    front: bool = True
    first_hit: int = -1  # blocked plans: first time index at which a predicted agent meets it (no wait)


class EgoPlanner:
    """§V-D decision logic; see the module docstring. One instance per episode (or call :meth:`reset`).

    Args:
        lot: the lot map (§II-A).
        settings: planner settings (validated).
    """

    def __init__(self, lot: LotMap, settings: PlannerSettings = PlannerSettings()):
        self.lot = lot
        self.settings = settings.validate()
        from avp_planner.core.hybrid_astar import rs_length_table

        s = settings.search
        rs_length_table(round(settings.plan_radius, 9), s.rs_table_resolution, s.rs_table_extent, s.heading_bins)
        self.reset()

    def reset(self) -> None:
        """Forget the internal beliefs and the plan being executed."""
        self.beliefs = np.full(self.lot.n_spots, 0.5)
        self._plan: _Plan | None = None
        self._world_cache: dict[tuple, StaticWorld] = {}
        self._last_park_attempt: tuple | None = None
        self._park_attempt_step = -(10**9)
        self._front_blocked_step: int | None = None  # since when the road ahead is blocked by agents only
        self._idle_until = -(10**9)  # idle_replan_steps: no new search before this step after an idle decision
        self._failed_searches: dict[tuple, PlanResult] = {}  # see FAILED_SEARCH_CACHE

    # ------------------------------------------------------------------------------------------ inputs
    def _check_inputs(self, obs: Observation, beliefs, predictions) -> str:
        pose = np.asarray(obs.ego_pose, dtype=float)
        if pose.shape != (3,) or not np.isfinite(pose).all():
            return "invalid input: NaN in ego pose"
        if not (math.isfinite(obs.ego_speed) and math.isfinite(obs.ego_length) and math.isfinite(obs.ego_width)):
            return "invalid input: NaN in ego speed or size"
        if obs.ego_length <= 0 or obs.ego_width <= 0:
            return "invalid input: ego size must be > 0"
        for v in obs.vehicles:
            if not (np.isfinite(v.history).all() and math.isfinite(v.length) and math.isfinite(v.width)):
                return f"invalid input: NaN in observed vehicle {v.id}"
        for p in obs.pedestrians:
            if not (np.isfinite(p.position).all() and np.isfinite(p.previous_position).all()
                    and math.isfinite(p.radius)):
                return f"invalid input: NaN in observed pedestrian {p.id}"
        for sid in (*np.asarray(obs.vacant_spot_ids).tolist(), *np.asarray(obs.occupied_spot_ids).tolist()):
            if not self.lot.has_spot(sid):
                return f"invalid input: unknown spot id {sid}"
        if beliefs is not None:
            b = np.asarray(beliefs, dtype=float)
            if b.shape != (self.lot.n_spots,):
                return f"invalid input: beliefs must have shape ({self.lot.n_spots},), got {b.shape}"
            if not np.isfinite(b).all():
                return "invalid input: NaN in beliefs"
            if b.min() < 0 or b.max() > 1:
                return "invalid input: beliefs must lie in [0, 1]"
        for p in predictions:
            if not np.isfinite(np.asarray(p.poses, dtype=float)).all() or not math.isfinite(p.dt) or p.dt <= 0:
                return f"invalid input: NaN in prediction of agent {p.agent_id}"
        return ""

    def update_beliefs(self, obs: Observation) -> np.ndarray:
        """§V-B first update without intentions: observed vacant -> 0, observed occupied -> 1, else kept."""
        for sid in np.asarray(obs.vacant_spot_ids).tolist():
            self.beliefs[self.lot.spot_index(sid)] = 0.0
        for sid in np.asarray(obs.occupied_spot_ids).tolist():
            self.beliefs[self.lot.spot_index(sid)] = 1.0
        return self.beliefs

    # --------------------------------------------------------------------------------------- worlds
    def _static_world(self, obs: Observation, beliefs: np.ndarray, extra: np.ndarray | None = None) -> StaticWorld:
        """The static obstacles: believed-occupied spots (b >= beta), observed static vehicles, and ``extra``.

        Built worlds are cached by what they are built from (the last ``WORLD_CACHE_SIZE``: parked cars at the
        sensor's edge flicker in and out of view). A static vehicle lying inside a believed-occupied spot with
        ``CONTAINED_MARGIN`` to spare adds nothing to the union of obstacles, nor to its raster, so it is left
        out of what the world is built from. ``world.key`` still names every input (the parking retry logic
        compares it), so decisions are those of a world built from everything.
        """
        d = self.settings.decision
        occ = np.nonzero(beliefs >= d.belief_threshold)[0]
        poses = [self.lot.spot_poses[occ]]
        dims = [self.lot.spot_dims[occ]]
        stat = [v for v in obs.vehicles if v.is_static]
        kept = []
        if stat:
            sp = np.array([v.pose for v in stat], dtype=float)
            sd = np.array([[v.length, v.width] for v in stat], dtype=float)
            poses.append(sp)
            dims.append(sd)
            kept = self._not_inside_occupied(sp, sd, occ)
        if extra is not None and len(extra):
            poses.append(extra[:, :3])
            dims.append(extra[:, 3:5])
        poses_a, dims_a = np.concatenate(poses), np.concatenate(dims)
        rp, rd = np.round(poses_a, 6), np.round(dims_a, 6)
        key = (float(obs.ego_length), float(obs.ego_width), rp.tobytes(), rd.tobytes())
        build = key
        if stat:  # build from the spots, the vehicles not inside them, and extra
            keep = np.r_[np.ones(len(occ), bool), kept, np.ones(len(poses_a) - len(occ) - len(stat), bool)]
            poses_a, dims_a = poses_a[keep], dims_a[keep]
            build = (key[0], key[1], rp[keep].tobytes(), rd[keep].tobytes())
        world = self._world_cache.get(build) if extra is None else None
        if world is None:
            world = StaticWorld(self.lot, poses_a, dims_a, obs.ego_length, obs.ego_width, self.settings.collision)
            if extra is None:
                self._world_cache[build] = world
                while len(self._world_cache) > WORLD_CACHE_SIZE:
                    self._world_cache.pop(next(iter(self._world_cache)))
        else:
            self._world_cache[build] = self._world_cache.pop(build)  # most recently used last
        world.key = key
        return world

    def _not_inside_occupied(self, poses: np.ndarray, dims: np.ndarray, occ: np.ndarray) -> np.ndarray:
        """(N,) bool: the vehicle rectangles not inside the nearest believed-occupied spot with
        ``CONTAINED_MARGIN`` to spare on every side."""
        if not len(occ):
            return np.ones(len(poses), bool)
        centres = self.lot.spot_poses[occ, :2]
        near = occ[np.argmin(((poses[:, None, :2] - centres[None]) ** 2).sum(-1), axis=1)]
        grown = rect_corners(poses, dims[:, 0] + 2 * CONTAINED_MARGIN, dims[:, 1] + 2 * CONTAINED_MARGIN)
        return ~rect_inside_rect(grown, self.lot.spot_corners[near])

    def _dynamic(self, obs: Observation, predictions: Sequence[PredictedTrajectory]) -> DynamicObstacles:
        dt = self.settings.control.dt
        d = self.settings.decision
        preds = [self._resample(p, dt) for p in predictions]
        covered = {(bool(p.is_pedestrian), int(p.agent_id)) for p in preds}
        if d.fallback_prediction != "none":
            n = max(1, int(round(d.fallback_horizon / dt)))
            for v in obs.vehicles:
                if v.is_static or (False, int(v.id)) in covered:
                    continue
                preds.append(self._fallback_vehicle(v, obs.dt, dt, n, d.fallback_prediction))
            for p in obs.pedestrians:
                if (True, int(p.id)) in covered:
                    continue
                vel = (np.asarray(p.position) - np.asarray(p.previous_position)) / obs.dt
                if d.fallback_prediction == "static":
                    vel = vel * 0.0
                k = np.arange(1, n + 1)[:, None] * dt
                pos = np.asarray(p.position, dtype=float)[None, :] + k * vel[None, :]
                preds.append(PredictedTrajectory(agent_id=int(p.id), poses=np.column_stack([pos, np.zeros(n)]),
                                                 dt=dt, is_pedestrian=True, radius=float(p.radius)))
        c = self.settings.collision
        return DynamicObstacles(preds, obs.ego_length, obs.ego_width, c.vehicle_margin, c.pedestrian_margin,
                                keep_current_gap=c.keep_current_gap, hold_last=c.beyond_horizon == "hold")

    @staticmethod
    def _resample(p: PredictedTrajectory, dt: float) -> PredictedTrajectory:
        if abs(p.dt - dt) < 1e-9 or len(p.poses) == 0:
            return p
        poses = np.asarray(p.poses, dtype=float).reshape(-1, 3)
        t_src = p.dt * np.arange(1, len(poses) + 1)
        n = max(1, int(math.floor(t_src[-1] / dt + 1e-9)))
        t = dt * np.arange(1, n + 1)
        th = np.unwrap(poses[:, 2])
        out = np.column_stack([np.interp(t, t_src, poses[:, 0]), np.interp(t, t_src, poses[:, 1]),
                               wrap(np.interp(t, t_src, th))])
        return PredictedTrajectory(agent_id=p.agent_id, poses=out, dt=dt, probability=p.probability,
                                   is_pedestrian=p.is_pedestrian, length=p.length, width=p.width, radius=p.radius,
                                   spot_id=p.spot_id)

    @staticmethod
    def _fallback_vehicle(v, obs_dt: float, dt: float, n: int, kind: str) -> PredictedTrajectory:
        """Constant (signed) speed and yaw rate from the last two history states, rolled out with eq. (1)."""
        hist = np.asarray(v.history, dtype=float).reshape(-1, 3)
        cur = hist[-1]
        speed, omega = 0.0, 0.0
        if kind == "constant_velocity" and len(hist) >= 2:
            prev = hist[-2]
            dxy = cur[:2] - prev[:2]
            speed = float(np.dot(dxy, [math.cos(prev[2]), math.sin(prev[2])])) / obs_dt
            omega = float(wrap(cur[2] - prev[2])) / obs_dt
        poses = np.empty((n, 3))
        s = cur.copy()
        u = np.array([speed, omega])
        for k in range(n):
            s = step_vehicle(s, u, dt)
            poses[k] = s
        return PredictedTrajectory(agent_id=int(v.id), poses=poses, dt=dt, length=float(v.length),
                                   width=float(v.width))

    def _agents_as_rects(self, obs: Observation) -> np.ndarray:
        """Current footprints of the observed dynamic agents that stand (nearly) still, as (x, y, θ, length,
        width) rows, grown so that a path keeping ``footprint_margin`` to them also keeps the dynamic margins.
        Moving agents are left out: for them waiting is the answer, not a detour."""
        c = self.settings.collision
        gv = 2.0 * max(c.vehicle_margin - c.footprint_margin, 0.0) + 0.04
        gp = 2.0 * max(c.pedestrian_margin - c.footprint_margin, 0.0) + 0.04
        rows = []
        for v in obs.vehicles:
            h = np.asarray(v.history, dtype=float).reshape(-1, 3)
            if not v.is_static and (len(h) < 2 or np.hypot(*(h[-1, :2] - h[-2, :2])) / obs.dt < STILL_SPEED):
                rows.append([*v.pose, v.length + gv, v.width + gv])
        for p in obs.pedestrians:
            if np.hypot(*(np.asarray(p.position) - np.asarray(p.previous_position))) / obs.dt < STILL_SPEED:
                rows.append([*p.position, 0.0, 2 * p.radius + gp, 2 * p.radius + gp])
        return np.array(rows, dtype=float).reshape(-1, 5)

    # ------------------------------------------------------------------------------------ candidates
    def candidate_spots(self, obs: Observation, beliefs: np.ndarray) -> np.ndarray:
        """Indices (into ``lot.spots``) of I_can,0 = {i in I_vac,t : b_t,i <= δ} (§V-D-1)."""
        idx = [self.lot.spot_index(s) for s in np.asarray(obs.vacant_spot_ids).tolist()]
        idx = sorted(i for i in idx if beliefs[i] <= self.settings.decision.candidate_threshold)
        return np.asarray(idx, dtype=np.int64)

    def _prioritised(self, cands: np.ndarray, priority: Sequence[int], ego: np.ndarray) -> np.ndarray:
        """Candidate rows in the order of ``priority`` (spot ids); the rest after them, nearest first."""
        rank = {}
        for sid in priority:
            if self.lot.has_spot(int(sid)):
                rank.setdefault(self.lot.spot_index(int(sid)), len(rank))
        listed = sorted((int(i) for i in cands if int(i) in rank), key=lambda i: rank[i])
        rest = [int(i) for i in cands if int(i) not in rank]
        dist = {i: math.hypot(*(self.lot.spot_poses[i, :2] - ego[:2])) for i in rest}
        rest.sort(key=lambda i: (dist[i], i))
        return np.asarray(listed + rest, dtype=np.int64)

    def spot_goals(self, k: int) -> np.ndarray:
        """The two goal poses of spot row ``k``: centred, spot heading and spot heading + π."""
        x, y, th = self.lot.spot_poses[k]
        return np.array([[x, y, th], [x, y, float(wrap(th + math.pi))]])

    def exploration_points(self, ego: np.ndarray) -> list[tuple[np.ndarray, bool, int]]:
        """§V-D-2: crossings of the road centre lines with the sensing circle, heading away from the ego.

        Returns [(pose (3,), in_front, road id)], front points first, each group sorted by road id and angle.
        """
        r = self.settings.decision.sensing_radius
        p = np.asarray(ego[:2], dtype=float)
        head = np.array([math.cos(ego[2]), math.sin(ego[2])])
        out = []
        for road in self.lot.roads:
            a, b = np.asarray(road.start, dtype=float), np.asarray(road.end, dtype=float)
            dvec = b - a
            aa = float(dvec @ dvec)
            f = a - p
            bb = 2.0 * float(f @ dvec)
            cc = float(f @ f) - r * r
            disc = bb * bb - 4 * aa * cc
            if disc < 0:
                continue
            sq = math.sqrt(disc)
            for t in sorted({(-bb - sq) / (2 * aa), (-bb + sq) / (2 * aa)}):
                if not (-1e-9 <= t <= 1 + 1e-9):
                    continue
                q = a + t * dvec
                u = dvec / math.sqrt(aa)
                th = road.heading if float(u @ (q - p)) >= 0 else road.heading + math.pi
                front = float(head @ (q - p)) >= 0
                out.append((np.array([q[0], q[1], float(wrap(th))]), front, road.id))
        out.sort(key=lambda e: (not e[1], e[2], e[0][0], e[0][1]))
        return out

    def _explore_goal(self, point: np.ndarray, world: StaticWorld) -> np.ndarray | None:
        d = self.settings.decision
        th = float(point[2])
        c, s = math.cos(th), math.sin(th)
        base = point[:2] + d.explore_lane_offset * np.array([s, -c])  # right of the heading
        for slide in d.explore_goal_slide:
            g = np.array([base[0] + slide * c, base[1] + slide * s, th])
            if world.free(g[None], self.settings.collision.footprint_margin)[0]:
                return g
        return None

    # --------------------------------------------------------------------------------------- pricing
    def _lower_bound(self, ego: np.ndarray, goals: np.ndarray, heur: EgoHeuristic) -> float:
        """Lower bound of c for any plan to ``goals``: (w_length + w_time / v_max) times the larger of the exact
        obstacle-free Reeds-Shepp length (radius R_plan) and the 2-D grid distance made a lower bound (octile
        paths are at most 8.24 % longer than straight lines; cell centres are up to half a diagonal off)."""
        cs, ctl = self.settings.cost, self.settings.control
        lb = math.inf
        d2 = heur.dist2d(goals[:, :2]) / 1.0824 - math.sqrt(2.0) * heur.h_res
        for g, dd in zip(goals, d2, strict=True):
            length, _ = rs_shortest(tuple(g), tuple(ego), self.settings.plan_radius)
            lb = min(lb, max(length, float(dd)))
        return (cs.w_length + cs.w_time / ctl.v_max) * lb

    def _price(self, path: Path, world: StaticWorld, dyn: DynamicObstacles, v0: float):
        """(cost, wait_steps, first_hit) of the path started after the first feasible wait; (inf, -1, k) when
        every wait meets a predicted agent, k being the first such time index without waiting."""
        cs, ctl, d = self.settings.cost, self.settings.control, self.settings.decision
        dt = ctl.dt
        poses, speeds = reference_trajectory(path, ctl, v0)
        ds = np.abs(speeds) * dt
        clr = world.footprint_clearance(poses[1:])
        base = (cs.w_length * path.length + cs.w_reverse * path.reverse_length + cs.w_switch * path.n_switches
                + cs.w_static * float(np.sum(np.exp(-3.0 * np.maximum(clr, 0.0)) * ds)))
        n_wait = int(round(d.max_wait / dt))
        step = max(1, int(round(d.wait_step / dt)))
        first_hit = -1
        for w in range(0, n_wait + 1, step):
            ego = np.concatenate([np.repeat(poses[:1], w, axis=0), poses]) if w else poses
            hit = dyn.first_collision(ego)
            if w == 0:
                first_hit = hit
            if hit >= 0:
                continue
            t_total = (len(speeds) + w) * dt
            cost = base + cs.w_time * t_total + cs.w_dynamic * dyn.proximity_cost(ego, dt)
            return cost, w, -1
        return math.inf, -1, first_hit

    # ------------------------------------------------------------------------------------- planning
    def _search_set(self, mode: str, items, ego, world, dyn, heur, astar, v0, t_end, stats, timing, blocked_out,
                    max_iterations: int | None = None, first_feasible: bool = False):
        """Plan to each item (spot row index or exploration point) with branch and bound on c.

        Returns the feasible candidates sorted by cost, and whether some static path existed but every
        one was blocked by predicted agents (those are appended to ``blocked_out``). ``first_feasible``: the
        items are tried in the given order (no lower bounds, no branch and bound) and the first feasible
        plan ends the search (the implicit method's spot priority, ``decide(spot_priority=...)``).
        """
        entries = []
        for it in items:
            goals = self.spot_goals(it) if mode == PARK else it[0][None]
            entries.append((0.0 if first_feasible else self._lower_bound(ego, goals, heur), it, goals))
        if not first_feasible:
            entries.sort(key=lambda e: e[0])
        found: list[_Candidate] = []
        blocked_by_agents = False
        best = math.inf
        for lb, it, goals in entries[: self.settings.decision.max_candidates_planned]:
            if found and first_feasible:
                break
            if (lb >= best and self.settings.decision.branch_and_bound) or time.perf_counter() > t_end:
                break
            t0 = time.perf_counter()
            max_length = self.settings.decision.explore_max_length if mode == EXPLORE else None
            memo = (astar.world.key, astar.ego.tobytes(), np.asarray(goals, float).tobytes(), max_iterations,
                    max_length)
            res: PlanResult | None = self._failed_searches.get(memo)
            if res is None:
                res = astar.plan(goals, max_iterations=max_iterations,
                                 time_cap=min(self.settings.search.time_cap, max(t_end - t0, 1e-3)),
                                 max_length=max_length)
                if not res.success and not res.reason.startswith("time cap"):  # a repeatable failure
                    self._failed_searches[memo] = res
                    while len(self._failed_searches) > FAILED_SEARCH_CACHE:
                        self._failed_searches.pop(next(iter(self._failed_searches)))
            dt_q = time.perf_counter() - t0
            timing["path_planning_time"] += dt_q
            stats.setdefault("queries", []).append({"mode": mode, "target": int(it) if mode == PARK else -1,
                                                    "success": res.success, "reason": res.reason,
                                                    "time_s": dt_q, "iterations": res.stats.get("iterations", 0)})
            if not res.success:
                continue
            t1 = time.perf_counter()
            cost, wait, hit = self._price(res.path, world, dyn, v0)
            timing["spot_selection_time"] += time.perf_counter() - t1
            if wait < 0:
                blocked_by_agents = True
                blocked_out.append(_Candidate(mode, int(self.lot.spot_ids[it]) if mode == PARK else -1, res.goal,
                                              res.path, math.inf, 0, True, hit))
                continue
            found.append(_Candidate(mode, int(self.lot.spot_ids[it]) if mode == PARK else -1, res.goal, res.path,
                                    cost, wait, True if mode == PARK else bool(it[1])))
            best = min(best, cost)
        found.sort(key=lambda c: c.cost)
        return found, blocked_by_agents

    def _adopt(self, cands: list[_Candidate], world: StaticWorld, dyn: DynamicObstacles, obs: Observation,
               timing: dict, require_dynamic: bool = True) -> _Plan | None:
        """Track the cheapest candidate into controls and verify; fall back to the next one."""
        c = self.settings.collision
        for cand in cands:
            t0 = time.perf_counter()
            traj = track(cand.path, self.settings.control, self.settings.vehicle.max_curvature, obs.ego_speed)
            timing["path_planning_time"] += time.perf_counter() - t0
            if cand.wait_steps:
                z = np.zeros((cand.wait_steps, 2))
                st = np.repeat(traj.states[:1], cand.wait_steps, axis=0)
                traj = Trajectory(np.concatenate([z, traj.controls]), np.concatenate([st, traj.states]), traj.dt)
            relax = np.cumsum(np.r_[0.0, np.hypot(*np.diff(traj.states[:, :2], axis=0).T)]) < c.start_relax_distance
            margins = np.where(relax, 0.0, c.verify_margin)
            st = traj.states
            ok = world.free_xyc(st[:, 0], st[:, 1], np.cos(st[:, 2]), np.sin(st[:, 2]), margins).all()
            if ok and cand.mode == PARK:
                ok = self._parked_in(traj.states[-1], cand.goal, cand.spot_id, obs)
            if ok and (not require_dynamic or dyn.first_collision(traj.states) < 0):
                return _Plan(cand.mode, cand.spot_id, cand.goal, traj, cand.cost, margins, 0, cand.path.length)
        return None

    def _parked_in(self, final: np.ndarray, goal: np.ndarray, spot_id: int, obs: Observation) -> bool:
        """The tracked end state is within the goal tolerance and its footprint inside the spot (V_0 ⊆ S_i)."""
        s = self.settings.search
        if math.hypot(final[0] - goal[0], final[1] - goal[1]) > s.goal_tolerance_xy:
            return False
        if abs(float(wrap(final[2] - goal[2]))) > s.goal_tolerance_heading:
            return False
        k = self.lot.spot_index(spot_id)
        fp = rect_corners(final, obs.ego_length, obs.ego_width)
        return bool(rect_inside_rect(fp[None], self.lot.spot_corners[k][None])[0])

    # ------------------------------------------------------------------------------------------ main
    def decide(self, obs: Observation, beliefs: np.ndarray | None = None,
               predictions: Sequence[PredictedTrajectory] = (), spot_priority: Sequence[int] | None = None
               ) -> Decision:
        """One decision step of §V-D (see the module docstring).

        ``spot_priority`` (spot ids, most wanted first; the "Implicit" method of §VI-B-3): the candidate spots
        are tried in that order — candidates not listed last, nearest first — and the first one with a safe
        plan is taken instead of the lowest c_park.
        """
        t_start = time.perf_counter()
        timing = {"spot_selection_time": 0.0, "path_planning_time": 0.0, "total": 0.0}
        stats: dict = {}
        predictions = list(predictions or ())
        bad = self._check_inputs(obs, beliefs, predictions)
        if bad:
            self._plan = None
            return self._finish(Decision(IDLE, reason=bad), timing, t_start)
        d = self.settings.decision
        if self._plan is None and obs.step < self._idle_until:  # stay put until the next idle re-plan (§V-D-3)
            if beliefs is None:
                self.update_beliefs(obs)
            return self._finish(Decision(IDLE, reason=f"waiting: re-plan at step {self._idle_until} "
                                                      "(idle_replan_steps)", poses=np.asarray(obs.ego_pose,
                                                                                             float)[None].copy()),
                                timing, t_start)
        b = self.update_beliefs(obs).copy() if beliefs is None else np.asarray(beliefs, dtype=float)
        ego = np.asarray(obs.ego_pose, dtype=float)
        t0 = time.perf_counter()
        world = self._static_world(obs, b)
        dyn = self._dynamic(obs, predictions)
        cands = self.candidate_spots(obs, b)
        ordered = spot_priority is not None
        if ordered:
            cands = self._prioritised(cands, spot_priority, ego)
        timing["spot_selection_time"] += time.perf_counter() - t0
        why = ""

        # ---- 1. the plan being executed
        keep_explore: _Plan | None = None
        p = self._plan
        if p is not None and p.mode == PARK and p.index >= len(p.traj.controls):
            if math.hypot(*(p.traj.states[-1][:2] - ego[:2])) <= d.replan_pose_tolerance:
                return self._finish(Decision(IDLE, spot_id=p.spot_id, goal=p.goal.copy(), poses=ego[None].copy(),
                                             n_candidates=len(cands), reason="parked"), timing, t_start)
        if self._plan is not None:
            ok, why = self._still_valid(self._plan, ego, world, dyn)
            if ok and self._plan.mode == PARK:
                return self._finish(self._execute(self._plan, len(cands), "executing"), timing, t_start)
            if ok:
                keep_explore = self._plan
            else:
                self._plan = None

        # ---- 2. parking
        t_end = t_start + d.decision_time_cap
        heur = None
        attempt_key = (world.key, tuple(cands.tolist()), tuple(np.floor(ego[:2]).astype(int).tolist()))
        retry = (keep_explore is None or attempt_key != self._last_park_attempt
                 or obs.step - self._park_attempt_step >= d.park_retry_steps)
        blocked = False
        blocked_plans: list[_Candidate] = []
        if len(cands) and retry:
            self._last_park_attempt, self._park_attempt_step = attempt_key, obs.step
            heur, astar = self._searcher(world, ego, timing)
            found, blocked = self._search_set(PARK, cands.tolist(), ego, world, dyn, heur, astar, obs.ego_speed,
                                              t_end, stats, timing, blocked_plans, first_feasible=ordered)
            plan = self._adopt(found, world, dyn, obs, timing)
            if plan is not None:
                self._plan = plan
                return self._finish(self._execute(plan, len(cands), "new parking plan", True), timing, t_start,
                                    stats)

        # ---- 3. exploration
        if keep_explore is not None:
            return self._finish(self._execute(keep_explore, len(cands), "exploring"), timing, t_start, stats)
        if heur is None:
            heur, astar = self._searcher(world, ego, timing)
        dt = self.settings.control.dt
        back_ok = (self._front_blocked_step is not None
                   and (obs.step - self._front_blocked_step) * dt >= EXPLORE_BACK_AFTER - 1e-9)
        plan, blocked_e, front_waits = self._explore(ego, world, dyn, heur, astar, obs, t_end, stats, timing,
                                                     blocked_plans, None, back_ok)
        if front_waits:
            if self._front_blocked_step is None:
                self._front_blocked_step = obs.step
        else:
            self._front_blocked_step = None
        blocked |= blocked_e
        if plan is None and blocked and d.dynamic_as_static_fallback:
            extra = self._agents_as_rects(obs)
            if len(extra):
                t_fb = min(t_end, time.perf_counter() + d.fallback_time_cap)
                it_fb = d.fallback_max_iterations
                world2 = self._static_world(obs, b, extra)
                heur2, astar2 = self._searcher(world2, ego, timing)
                if len(cands):
                    found, _ = self._search_set(PARK, cands.tolist(), ego, world, dyn, heur2, astar2,
                                                obs.ego_speed, t_fb, stats, timing, blocked_plans, it_fb, ordered)
                    plan = self._adopt(found, world, dyn, obs, timing)
                if plan is None:
                    plan, _, _ = self._explore(ego, world, dyn, heur2, astar2, obs, t_fb, stats, timing,
                                               blocked_plans, it_fb, back_ok)
                if plan is not None:
                    stats["around_agents"] = True
        if plan is not None:
            self._plan = plan
            what = "new parking plan around agents" if plan.mode == PARK else "new exploration plan"
            return self._finish(self._execute(plan, len(cands), what, True), timing, t_start, stats)

        # ---- 4. idle, unless standing still is itself predicted to be hit: then the blocked plan that meets
        # the predicted agents latest (later than standing still) is driven, re-checked every step
        if d.evasive:
            plan = self._evade(ego, world, dyn, obs, blocked_plans, timing)
            if plan is not None:
                self._plan = plan
                stats["evasive"] = True
                return self._finish(self._execute(plan, len(cands), plan.note, True), timing, t_start, stats)
        reason = "no safe parking or exploration plan" + (f" ({why})" if why else "")
        self._idle_until = obs.step + d.idle_replan_steps
        return self._finish(Decision(IDLE, n_candidates=len(cands), reason=reason, poses=ego[None].copy()),
                            timing, t_start, stats)

    def _evade(self, ego, world, dyn, obs, blocked_plans, timing) -> _Plan | None:
        """If standing still is predicted to be hit, drive whatever is hit latest (or never): the blocked
        plans of this step and short escape arcs (every curvature of the steering set, forward and reverse,
        2 to 8 m). Returns None when standing still is safe or nothing does better."""
        if dyn.empty:
            return None
        standing = dyn.first_collision(np.repeat(ego[None], dyn.horizon + 2, axis=0))
        if standing < 0:
            return None
        t0 = time.perf_counter()
        kap = 1.0 / self.settings.plan_radius
        cands = list(blocked_plans)
        start = (float(ego[0]), float(ego[1]), float(ego[2]))
        for direction in (-1.0, 1.0):
            for f in self.settings.search.steering_fractions:
                for length in (2.0, 4.0, 6.0, 8.0):
                    path = Path(start, ((f * kap, direction * length),))
                    poses, _ = reference_trajectory(path, self.settings.control, obs.ego_speed)
                    if not world.free(poses[1:], self.settings.collision.verify_margin).all():
                        continue
                    cands.append(_Candidate(EXPLORE, -1, path.end(), path, math.inf, 0, False,
                                            dyn.first_collision(poses)))
        timing["spot_selection_time"] += time.perf_counter() - t0

        def later(c: _Candidate) -> tuple:
            return (-(c.first_hit if c.first_hit >= 0 else 10**9), c.path.length)

        order = sorted((c for c in cands if c.first_hit < 0 or c.first_hit > standing), key=later)
        plan = self._adopt(order[:3], world, dyn, obs, timing, require_dynamic=False)
        if plan is not None:
            plan.note = f"evasive: standing still is hit at step {standing}"
        return plan

    def _searcher(self, world: StaticWorld, ego: np.ndarray, timing: dict):
        t0 = time.perf_counter()
        heur = EgoHeuristic(world, ego, self.settings)
        timing["path_planning_time"] += time.perf_counter() - t0
        return heur, HybridAStar(world, ego, self.settings, heur)

    def _explore(self, ego, world, dyn, heur, astar, obs, t_end, stats, timing, blocked_out,
                 max_iterations: int | None = None, back_allowed: bool = True):
        """Front exploration points, then (if allowed) those behind. Returns (plan or None, some path blocked by
        predicted agents, the front had paths but all were blocked by predicted agents)."""
        pts = []
        for pose, front, rid in self.exploration_points(ego):
            g = self._explore_goal(pose, world)
            if g is not None and math.hypot(g[0] - ego[0], g[1] - ego[1]) > 1.0:
                pts.append((g, front, rid))
        blocked_any = front_waits = False
        for group in (True, False):  # front points first; behind only if the front stays blocked
            items = [p for p in pts if p[1] == group]
            if group is False and front_waits and not back_allowed:
                break  # the road ahead is blocked by agents only: wait before turning back
            if not items:
                continue
            found, blocked = self._search_set(EXPLORE, items, ego, world, dyn, heur, astar, obs.ego_speed, t_end,
                                              stats, timing, blocked_out, max_iterations)
            blocked_any |= blocked
            plan = self._adopt(found, world, dyn, obs, timing)
            if plan is not None:
                return plan, blocked_any, False
            if group:
                front_waits = blocked
        return None, blocked_any, front_waits

    def _still_valid(self, plan: _Plan, ego: np.ndarray, world: StaticWorld, dyn: DynamicObstacles) -> tuple[bool, str]:
        d = self.settings.decision
        k = plan.index
        if k >= len(plan.traj.controls):
            return False, "plan finished"
        exp = plan.traj.states[k]
        if math.hypot(*(exp[:2] - ego[:2])) > d.replan_pose_tolerance or abs(float(wrap(exp[2] - ego[2]))) > 0.02:
            return False, "ego off the plan"
        rest = plan.traj.states[k:]
        r1 = rest[1:]
        if not world.free_xyc(r1[:, 0], r1[:, 1], np.cos(r1[:, 2]), np.sin(r1[:, 2]), plan.margins[k + 1:]).all():
            return False, "static obstacle on the plan"
        if dyn.first_collision(rest) >= 0:
            return False, "predicted agent on the plan"
        if plan.mode == EXPLORE:
            left = np.abs(plan.traj.controls[k:, 0]).sum() * plan.traj.dt
            if left < d.explore_replan_distance:
                return False, "exploration plan nearly done"
        return True, ""

    def _execute(self, plan: _Plan, n_cand: int, reason: str, new: bool = False) -> Decision:
        k = plan.index
        u = plan.traj.controls[k]
        plan.index += 1
        return Decision(plan.mode, spot_id=plan.spot_id, goal=plan.goal.copy(), poses=plan.traj.states[k:].copy(),
                        controls=plan.traj.controls[k:].copy(), command=(float(u[0]), float(u[1])),
                        n_candidates=n_cand, reason=reason, cost=plan.cost, replanned=new)

    @staticmethod
    def _finish(dec: Decision, timing: dict, t_start: float, stats: dict | None = None) -> Decision:
        timing["total"] = time.perf_counter() - t_start
        dec.timings = timing
        if stats:
            dec.stats.update(stats)
        return dec

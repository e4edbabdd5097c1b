"""Hybrid A* trajectory prediction (an alternative to the Bezier curves of §V-C), ROS-free.

``make_predictor("hybrid_astar", lot)``; the interface of :mod:`.prediction`: ``predict(obs, intentions,
horizon) -> list[PredictedTrajectory]`` with ``poses[j]`` at t + (j + 1) dt.

For every observed dynamic vehicle V_k and every intention with probability >= mu (spots with eta_k,i >= mu,
exploration points with eta_hat_k,q >= mu — the goals of the Bezier predictor), a path from V_k's pose to
the goal is planned with the ego planner's Hybrid A* (:mod:`avp_search.hybrid_astar`, §V-D: arcs at
1.1 R_min forward and reverse, Reeds-Shepp shots, searched from the goal back to the vehicle). A spot goal is
the spot centre with the spot heading or its opposite (both seeds of one search: the car may park forwards
or backwards); an exploration goal is the point with its road heading. The path is followed at the constant
speed v = max(v_hat, ``min_speed``), v_hat = |p_t - p_t-dt| / dt (the speed of eq. 9-12), i.e. s_j = v (j + 1) dt
of arc length, for up to t_pred; headings are the path's (a reversing leg keeps the car's heading).
After t_pred the vehicle keeps going at v along its direction of motion (the constant-velocity fill of §V-C);
a vehicle that reaches its spot before t_pred stays there (parked); one that reaches an exploration point
keeps going along the road heading. Each trajectory carries the intention's probability, spot id and goal.

No path (start or goal in collision, unreachable, the ``max_iterations`` cap, a path longer than
``max_length``) or v = 0: the intention's trajectory is constant velocity (p_t + j (p_t - p_t-dt), heading
kept — standing still for a stopped car), still carrying the intention's probability. A vehicle without an
intention, with none >= mu, or whose "none" mass >= mu has no exploration point, is predicted at constant
velocity exactly like the Bezier predictor; pedestrians at constant velocity (§V-C).

**Static world of V_k.** The observation only (no belief map reaches the prediction node): every spot
rectangle counts as an obstacle — agents drive on the roads and enter only the spot they park in, and
this keeps the same world from step to step — except the goal spots (>= mu) of the observed vehicles and
any spot that an observed dynamic vehicle's current footprint meets (a car already half-way into or out
of a spot must be able to start); plus the observed static vehicles and the lot boundary L. The ego and the
other moving vehicles are not obstacles (they move; the ego planner handles the interaction). The
:class:`~avp_collision.static.StaticWorld` (occupancy grid + distance transform) is cached under that
obstacle set and the footprint size, so it is rebuilt only when the set changes; the obstacle-aware 2-D
heuristic (:class:`~avp_search.heuristic.EgoHeuristic`, rooted at the vehicle) is built once per vehicle
and step and shared by its goals, and its 2-D distance map is reused while the vehicle stays in the same
start cell of the same world (the heuristic's ``cache``); the Reeds-Shepp length table once per process.

Only iteration caps decide the searches (``time_cap`` is a wall-clock safety net set far above the
iteration cap's cost), so the predictions are deterministic.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace

import numpy as np

from avp_collision.static import StaticWorld
from avp_predictors.intention import Intention
from avp_predictors.prediction import (
    BezierPredictor,
    PredictionConfig,
    _n_steps,
    complete_predictions,
    constant_velocity_pedestrian,
    constant_velocity_vehicle,
    intention_trajectory,
    vehicle_motion,
)
from avp_search.heuristic import EgoHeuristic, rs_length_table
from avp_search.hybrid_astar import HybridAStar
from avp_search.paths import Path
from avp_search.settings import SearchConfig
from avp_world.geometry import rect_corners, rects_overlap, wrap_angle
from avp_world.lot import LotMap
from avp_world.types import Observation, ObservedVehicle, PredictedTrajectory

WORLD_CACHE_SIZE = 8  # static worlds kept (one per obstacle set and footprint size)


def spot_goal_poses(lot: LotMap, row: int) -> np.ndarray:
    """(2, 3): spot ``row``'s centre with the spot heading and with the opposite heading."""
    x, y, th = (float(v) for v in lot.spot_poses[row])
    return np.array([[x, y, th], [x, y, float(wrap_angle(th + np.pi))]])


def follow_path(path: Path, speed: float, dt: float, n_steps: int, n_path: int, hold_at_end: bool) -> np.ndarray:
    """(n_steps, 3) poses at t + dt ... travelling along ``path`` at constant ``speed``: arc length
    s_j = speed (j + 1) dt for the first ``n_path`` steps (clipped to the path's end), then straight on along
    the direction of motion at the same speed — or, if the path ended within those steps and ``hold_at_end``,
    standing at its end pose."""
    out = np.empty((n_steps, 3))
    if n_steps == 0:
        return out
    length = path.length
    s = speed * dt * np.arange(1, n_steps + 1)
    s_anchor = min(length, speed * dt * n_path)
    on = s <= s_anchor + 1e-12
    n_on = int(on.sum())
    out[:n_on] = path.poses_at(s[:n_on])
    if n_on == n_steps:
        return out
    anchor = path.poses_at(np.array([s_anchor]))[0]
    if hold_at_end and s_anchor >= length - 1e-9:
        out[n_on:] = anchor
        return out
    sign = 1.0
    if path.segments:
        bounds = np.concatenate([[0.0], np.cumsum([abs(ell) for _, ell in path.segments])])
        j = int(np.clip(np.searchsorted(bounds, s_anchor, side="left") - 1, 0, len(path.segments) - 1))
        sign = 1.0 if path.segments[j][1] > 0 else -1.0
    direction = sign * np.array([np.cos(anchor[2]), np.sin(anchor[2])])
    out[n_on:, :2] = anchor[:2] + (s[n_on:] - s_anchor)[:, None] * direction
    out[n_on:, 2] = anchor[2]
    return out


class HybridAStarPredictor(BezierPredictor):
    """Intention-conditioned prediction along Hybrid A* paths (see the module docstring).

    Args:
        lot: the lot map (spot poses are the goals, L and the spots the static world).
        config: §V-C parameters; ``config.hybrid_astar`` holds the search caps and the speed floor.
        planner_settings: vehicle kinematics, collision and search settings of the planner core (its
            defaults: the ParkSim car, R_min = 3.22 m); the caps and margin of ``config.hybrid_astar`` override
            theirs.
    """

    name = "hybrid_astar"

    def __init__(self, lot: LotMap, config: PredictionConfig = PredictionConfig(),
                 planner_settings: SearchConfig | None = None):
        super().__init__(lot, config)
        a = self.config.hybrid_astar
        base = planner_settings if planner_settings is not None else SearchConfig()
        collision = replace(base.collision, footprint_margin=a.footprint_margin,
                            verify_margin=min(base.collision.verify_margin, a.footprint_margin))
        search = replace(base.search, max_iterations=int(a.max_iterations), time_cap=float(a.time_cap))
        self.settings = replace(base, collision=collision, search=search).validate()
        s = self.settings.search
        rs_length_table(round(self.settings.plan_radius, 9), s.rs_table_resolution, s.rs_table_extent,
                        s.heading_bins)  # built once per process (seconds); warm it here, not in the first step
        self._worlds: dict[tuple, StaticWorld] = {}
        self._heuristics: dict[tuple, tuple] = {}
        self.last_stats: dict = {}

    # ------------------------------------------------------------------------------------------ world
    def free_spot_rows(self, obs: Observation, goals: Iterable[tuple[np.ndarray, float, int]]) -> np.ndarray:
        """Rows of the spots that are not obstacles: goal spots, and spots an observed dynamic vehicle's
        current footprint meets (within twice the footprint margin)."""
        lot = self.lot
        free = {lot.spot_index(sid) for _, _, sid in goals if sid >= 0}
        dyn = [v for v in obs.vehicles if not v.is_static]
        if dyn and lot.n_spots:
            poses = np.array([v.pose for v in dyn], dtype=float)
            dims = np.array([[v.length, v.width] for v in dyn], dtype=float)
            corners = rect_corners(poses, dims[:, 0], dims[:, 1])
            hit = rects_overlap(lot.spot_corners[None, :], corners[:, None],
                                2.0 * self.settings.collision.footprint_margin)  # (V, N_S)
            free.update(np.nonzero(hit.any(axis=0))[0].tolist())
        return np.array(sorted(free), dtype=np.int64)

    def static_world(self, obs: Observation, free_rows: np.ndarray, length: float, width: float) -> StaticWorld:
        """The cached static world: spots not in ``free_rows``, observed static vehicles, L (footprint l x w)."""
        lot = self.lot
        rows = np.setdiff1d(np.arange(lot.n_spots), free_rows)
        stat = [v for v in obs.vehicles if v.is_static]
        sp = np.array([v.pose for v in stat], dtype=float).reshape(-1, 3)
        sd = np.array([[v.length, v.width] for v in stat], dtype=float).reshape(-1, 2)
        key = (rows.tobytes(), np.round(sp, 6).tobytes(), np.round(sd, 6).tobytes(), round(float(length), 6),
               round(float(width), 6))
        world = self._worlds.get(key)
        if world is None:
            if len(self._worlds) >= WORLD_CACHE_SIZE:
                self._worlds.clear()
            world = StaticWorld(lot, np.concatenate([lot.spot_poses[rows], sp]),
                                np.concatenate([lot.spot_dims[rows], sd]), length, width, self.settings.collision)
            world.key = key
            self._worlds[key] = world
            self.last_stats["worlds_built"] = self.last_stats.get("worlds_built", 0) + 1
        return world

    # ------------------------------------------------------------------------------------- prediction
    def predict_vehicle_astar(self, obs: Observation, vehicle: ObservedVehicle, intention: Intention | None,
                              free_rows: np.ndarray, n_steps: int) -> list[PredictedTrajectory]:
        """Trajectories of one observed dynamic vehicle (one per intention >= mu; see the module docstring)."""
        cfg, dt = self.config, obs.dt
        if intention is None:
            return [constant_velocity_vehicle(vehicle, dt, n_steps)]
        pose = np.asarray(vehicle.pose, dtype=float)
        speed, _ = vehicle_motion(vehicle.history, dt)
        v = max(speed, cfg.hybrid_astar.min_speed)
        n_path = min(n_steps, _n_steps(cfg.t_pred, dt))
        goals = self.goals(intention)
        st = self.last_stats
        astar: HybridAStar | None = None
        out = []
        for goal, p, sid in goals:
            poses = None
            if v > 0.0 and n_path > 0:
                if astar is None:  # one search object and heuristic per vehicle and step, shared by its goals
                    world = self.static_world(obs, free_rows, vehicle.length, vehicle.width)
                    astar = HybridAStar(world, pose, self.settings,
                                        EgoHeuristic(world, pose, self.settings, cache=self._heuristics))
                targets = spot_goal_poses(self.lot, self.lot.spot_index(sid)) if sid >= 0 else goal[None]
                res = astar.plan(targets, max_length=cfg.hybrid_astar.max_length)
                st["queries"] = st.get("queries", 0) + 1
                st["iterations"] = st.get("iterations", 0) + int(res.stats.get("iterations", 0))
                if res.success and res.path is not None:
                    st["paths"] = st.get("paths", 0) + 1
                    poses = follow_path(res.path, v, dt, n_steps, n_path, hold_at_end=sid >= 0)
                else:
                    st.setdefault("failures", []).append((int(vehicle.id), int(sid), res.reason))
            if poses is None:  # no plan: constant velocity, still conditioned on this intention
                traj = constant_velocity_vehicle(vehicle, dt, n_steps, p)
                out.append(replace(traj, spot_id=int(sid), goal=np.asarray(goal, dtype=float).copy()))
            else:
                out.append(intention_trajectory(vehicle, poses, dt, p, sid, goal))
        return complete_predictions(out, vehicle, intention, dt, n_steps, cfg.mu)

    def predict(self, obs: Observation, intentions: Iterable[Intention] = (),
                horizon: float | None = None) -> list[PredictedTrajectory]:
        self.last_stats = {}
        n = _n_steps(self.horizon(horizon), obs.dt)
        by_id = {int(it.vehicle_id): it for it in intentions}
        dyn = [v for v in obs.vehicles if not v.is_static]
        all_goals = [g for v in dyn if int(v.id) in by_id for g in self.goals(by_id[int(v.id)])]
        free_rows = self.free_spot_rows(obs, all_goals)
        out: list[PredictedTrajectory] = []
        for v in dyn:
            out += self.predict_vehicle_astar(obs, v, by_id.get(int(v.id)), free_rows, n)
        out += [constant_velocity_pedestrian(p, obs.dt, n) for p in obs.pedestrians]
        return out

"""The planner's inputs (§V-D): checks, beliefs from observation, the static world (spots with b >= β,
static vehicles) and the dynamic obstacles (predictions, constant-velocity fallbacks).

A part of :class:`avp_planner.core.decision.EgoPlanner` (split by job).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from avp_collision.hypotheses import held_where_they_are, most_likely, receding_straight
from avp_collision.localisation import footprint_inside, localisation_margin, localised_lot
from avp_collision.static import DynamicObstacles, StaticWorld
from avp_motion.planner_types import (
    CONTAINED_MARGIN,
    STILL_SPEED,
    WORLD_CACHE_SIZE,
)
from avp_motion.yielding import yielding_predictions
from avp_search.paths import wrap
from avp_world.geometry import rect_corners, rect_inside_rect
from avp_world.kinematics import step_vehicle
from avp_world.lot import LotMap
from avp_world.types import Observation, PredictedTrajectory


class InputsMixin:
    """Methods of :class:`~avp_planner.core.decision.EgoPlanner`; see the module docstring."""

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

    def _static_world(self, obs: Observation, beliefs: np.ndarray, extra: np.ndarray | None = None,
                      base: StaticWorld | None = None) -> StaticWorld:
        """The static obstacles: believed-occupied spots (b >= beta), observed static vehicles, and ``extra``.

        Built worlds are cached by what they are built from (the last ``WORLD_CACHE_SIZE``: parked cars at the
        sensor's edge flicker in and out of view; the detour round's world with the standing agents as ``extra`` is
        the same step after step while the ego is held up). A static vehicle lying inside a believed-occupied spot with
        ``CONTAINED_MARGIN`` to spare adds nothing to the union of obstacles, nor to its raster, so it is left
        out of what the world is built from. ``world.key`` still names every input (the parking retry logic
        compares it), so decisions are those of a world built from everything. A world is built by extending the
        grid of one with fewer rectangles (the same world, built faster: :mod:`avp_collision.world_extend`): ``base``,
        this step's world without ``extra``, or else the world of the believed-occupied spots alone, which changes
        seldom while the vehicles' estimates move with the sensor's noise.
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
        lot, margin = self._planning_lot(obs)
        key = (float(obs.ego_length), float(obs.ego_width), rp.tobytes(), rd.tobytes(), margin)
        build = key
        if stat:  # build from the spots, the vehicles not inside them, and extra
            keep = np.r_[np.ones(len(occ), bool), kept, np.ones(len(poses_a) - len(occ) - len(stat), bool)]
            poses_a, dims_a = poses_a[keep], dims_a[keep]
            build = (key[0], key[1], rp[keep].tobytes(), rd[keep].tobytes(), margin)
        world = self._world_cache.get(build)
        if world is None:
            if extra is None or not len(extra):
                base = self._spots_world(occ, obs) if len(poses_a) > len(occ) else None
            world = StaticWorld(lot, poses_a, dims_a, obs.ego_length, obs.ego_width, self.settings.collision,
                                n_base=len(occ), merge_cache=self._merge_cache, base=base)
            self._world_cache[build] = world
            while len(self._world_cache) > WORLD_CACHE_SIZE:
                self._world_cache.pop(next(iter(self._world_cache)))
        else:
            self._world_cache[build] = self._world_cache.pop(build)  # most recently used last
        world.key = key
        return world

    def _spots_world(self, occ: np.ndarray, obs: Observation) -> StaticWorld:
        """The static world of the believed-occupied spots ``occ`` alone (cached: the last few)."""
        lot, margin = self._planning_lot(obs)
        key = (float(obs.ego_length), float(obs.ego_width), np.asarray(occ).tobytes(), margin)
        world = self._spots_cache.get(key)
        if world is None:
            world = StaticWorld(lot, self.lot.spot_poses[occ], self.lot.spot_dims[occ], obs.ego_length,
                                obs.ego_width, self.settings.collision, n_base=len(occ), merge_cache=self._merge_cache)
            self._spots_cache[key] = world
            while len(self._spots_cache) > 4:
                self._spots_cache.pop(next(iter(self._spots_cache)))
        return world

    def _planning_lot(self, obs: Observation) -> tuple[LotMap, float | tuple]:
        """(lot, key): the lot whose boundary the ego plans against and the key its static worlds are cached by: its
        localisation margin m (:mod:`avp_collision.localisation`; the lot itself, m = 0, for exact sensing or
        ``collision.localisation_sigmas`` 0), or (m, the ego's footprint) where ``collision.localisation_keep_start``
        keeps that footprint in L'."""
        m = localisation_margin(obs.ego_covariance, obs.ego_length, obs.ego_width,
                                self.settings.collision.localisation_sigmas)
        if m <= 0:
            return self.lot, 0.0
        cache = self.__dict__.setdefault("_localised_lots", {})
        if m not in cache:
            cache.clear()  # one margin an episode for a steady localiser
            cache[m] = localised_lot(self.lot, m)
        c = self.settings.collision
        if not c.localisation_keep_start:
            return cache[m], m
        ego = rect_corners(np.asarray(obs.ego_pose, float)[None], obs.ego_length, obs.ego_width)[0]
        step_key = (m, ego.tobytes())
        last = self.__dict__.get("_planning_lot_last")
        if last is not None and last[0] == step_key:  # the static world and the spots' world of one step ask alike
            return last[1]
        result = self._kept_start_lot(cache[m], m, ego, (m, np.round(ego, 3).tobytes()))
        self.__dict__["_planning_lot_last"] = (step_key, result)
        return result

    def _kept_start_lot(self, lot_m: LotMap, m: float, ego: np.ndarray, key: tuple) -> tuple[LotMap, float | tuple]:
        """``collision.localisation_keep_start`` (see :meth:`_planning_lot`): L' where it holds the ego's footprint,
        else L'' keeping it (cached under ``key``, the margin and the footprint)."""
        if footprint_inside(lot_m, ego):
            return lot_m, m
        # collision.localisation_keep_start: the ego's own footprint kept whole in L' (avp_collision.localisation),
        # grown by the search's clearance and a little more so that a path may leave it
        c = self.settings.collision
        grow = max(c.footprint_margin, c.verify_margin) + 0.05
        kept = self.__dict__.setdefault("_kept_lots", {})
        if key not in kept:
            kept.clear()  # the ego's pose moves: one at a time
            kept[key] = localised_lot(self.lot, m, keep=ego, grow=grow)
        return kept[key], key

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
        if self.settings.collision.hypotheses == "most_likely":
            preds = most_likely(preds)
        if self.settings.collision.receding == "straight":
            preds = receding_straight(preds, obs, dt, STILL_SPEED)
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
        if d.assume_yielding:
            preds = yielding_predictions(obs, preds, d.yield_lookahead, d.yield_margin, dt)
        c = self.settings.collision
        keys = self._reactive_keys()
        if c.reactive_steps > 0 and c.reactive_model == "hold":
            preds = held_where_they_are(preds, obs, keys)
        return DynamicObstacles(preds, obs.ego_length, obs.ego_width, c.vehicle_margin, c.pedestrian_margin,
                                keep_current_gap=c.keep_current_gap, hold_last=c.beyond_horizon == "hold",
                                commit_steps=int(round(c.commit_horizon / dt)), risk_bound=c.risk_bound,
                                hold_after_commit=c.beyond_commit == "hold", react_steps=c.reactive_steps,
                                react_margin=c.reactive_margin, react_keys=keys,
                                react_trigger=c.reactive_trigger)

    def _reactive_keys(self) -> frozenset | None:
        """The agents ``collision.reactive_steps`` applies to (``collision.reactive_evidence``): None = every one."""
        c = self.settings.collision
        if c.reactive_evidence == "told":  # named by the caller (tell_reacting), not observed
            return self._told_reacting
        seen = self._evidence.seen
        if c.reactive_evidence == "assumed" or (c.reactive_evidence == "lot" and seen):
            return None
        return frozenset(seen)

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
            if vehicle_stands(v, obs.dt):
                rows.append([*v.pose, v.length + gv, v.width + gv])
        for p in obs.pedestrians:
            if pedestrian_stands(p, obs.dt):
                rows.append([*p.position, 0.0, 2 * p.radius + gp, 2 * p.radius + gp])
        return np.array(rows, dtype=float).reshape(-1, 5)


def vehicle_stands(v, dt: float) -> bool:
    """An observed dynamic vehicle that moved less than ``STILL_SPEED`` between its last two states (or has one)."""
    h = np.asarray(v.history, dtype=float).reshape(-1, 3)
    return not v.is_static and (len(h) < 2 or np.hypot(*(h[-1, :2] - h[-2, :2])) / dt < STILL_SPEED)


def pedestrian_stands(p, dt: float) -> bool:
    """An observed pedestrian that moved less than ``STILL_SPEED`` since its previous position."""
    return np.hypot(*(np.asarray(p.position) - np.asarray(p.previous_position))) / dt < STILL_SPEED

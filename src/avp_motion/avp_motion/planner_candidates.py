"""Candidates and their price (§V-D-1, §V-D-2): candidate spots I_can,0, goals, exploration points, the
lower bound of c_park that orders the searches, and c_park of a planned path.

A part of :class:`avp_planner.core.decision.EgoPlanner` (split by job).
"""

from __future__ import annotations

import math

import numpy as np

from avp_collision.static import DynamicObstacles, StaticWorld
from avp_motion.control import reference_trajectory
from avp_motion.waiting import stop_and_wait
from avp_search.hybrid_astar import EgoHeuristic
from avp_search.paths import Path, wrap
from avp_search.rs_scalar import rs_shortest
from avp_world.types import Observation


class CandidatesMixin:
    """Methods of :class:`~avp_planner.core.decision.EgoPlanner`; see the module docstring."""

    def vacant_rows(self, obs: Observation) -> np.ndarray:
        """Indices (into ``lot.spots``) of the observed vacant spots I_vac,t, in the observation's order."""
        return np.asarray([self.lot.spot_index(s) for s in np.asarray(obs.vacant_spot_ids).tolist()], dtype=np.int64)

    def candidate_spots(self, obs: Observation, beliefs: np.ndarray) -> np.ndarray:
        """Indices (into ``lot.spots``) of I_can,0 = {i in I_vac,t : b_t,i <= δ} (§V-D-1)."""
        idx = sorted(int(i) for i in self.vacant_rows(obs) if beliefs[i] <= self.settings.decision.candidate_threshold)
        return np.asarray(idx, dtype=np.int64)

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
        """(cost, wait_steps, first_hit, stop_path) of the path started after the first feasible wait; (inf, -1, k,
        None) when every wait meets a predicted agent, k being the first such time index without waiting. With
        ``wait_anywhere`` (mechanism c) the wait may be at a stop on the way: ``stop_path`` is then the path with
        that stop (:mod:`avp_motion.waiting`), else None."""
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
            return cost, w, -1, None
        if d.wait_anywhere and first_hit > 0:  # mechanism c: stop on the way and wait there
            found = stop_and_wait(path, speeds, first_hit, dyn, ctl, d, v0)
            if found is not None:
                stop_path, w, ego = found
                cost = base + cs.w_time * (len(ego) - 1) * dt + cs.w_dynamic * dyn.proximity_cost(ego, dt)
                return cost, w, -1, stop_path
        return math.inf, -1, first_hit, None

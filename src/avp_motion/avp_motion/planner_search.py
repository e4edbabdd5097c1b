"""The searches of one decision (§V-D): Hybrid A* over a candidate set with branch and bound, adopting the
best feasible plan, exploring.

A part of :class:`avp_planner.core.decision.EgoPlanner` (split by job).
"""

from __future__ import annotations

import math
import time

import numpy as np

from avp_collision.static import DynamicObstacles, StaticWorld
from avp_motion.control import Trajectory, track
from avp_motion.planner_types import (
    EXPLORE,
    PARK,
    SEARCH_CACHE,
    _Candidate,
    _Plan,
)
from avp_motion.trace import blocker_trace
from avp_motion.waiting import insert_wait, stop_index
from avp_search.hybrid_astar import EgoHeuristic, HybridAStar, PlanResult
from avp_search.paths import wrap
from avp_world.geometry import rect_corners, rect_inside_rect
from avp_world.types import Observation


class SearchMixin:
    """Methods of :class:`~avp_planner.core.decision.EgoPlanner`; see the module docstring."""

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
            bonus = self._commitment_bonus(mode, int(self.lot.spot_ids[it]) if mode == PARK else -1)  # 0: paper
            entries.append((0.0 if first_feasible else self._lower_bound(ego, goals, heur) - bonus, it, goals, bonus))
        if not first_feasible:
            entries.sort(key=lambda e: e[0])
        found: list[_Candidate] = []
        blocked_by_agents = False
        best = math.inf
        for lb, it, goals, bonus in entries[: self.settings.decision.max_candidates_planned]:
            if found and first_feasible:
                break
            if (lb >= best and self.settings.decision.branch_and_bound) or time.perf_counter() > t_end:
                break
            t0 = time.perf_counter()
            max_length = self.settings.decision.explore_max_length if mode == EXPLORE else None
            memo = (astar.world.key, astar.ego.tobytes(), np.asarray(goals, float).tobytes(), max_iterations,
                    max_length)
            res: PlanResult | None = self._searches.get(memo)
            if res is None:
                res = astar.plan(goals, max_iterations=max_iterations,
                                 time_cap=min(self.settings.search.time_cap, max(t_end - t0, 1e-3)),
                                 max_length=max_length)
                if res.success or not res.reason.startswith("time cap"):  # a repeatable outcome (SEARCH_CACHE)
                    self._searches[memo] = res
                    while len(self._searches) > SEARCH_CACHE:
                        self._searches.pop(next(iter(self._searches)))
            dt_q = time.perf_counter() - t0
            timing["path_planning_time"] += dt_q
            stats.setdefault("queries", []).append({"mode": mode, "target": int(it) if mode == PARK else -1,
                                                    "success": res.success, "reason": res.reason,
                                                    "time_s": dt_q, "iterations": res.stats.get("iterations", 0)})
            if not res.success:
                continue
            t1 = time.perf_counter()
            cost, wait, hit, stop_path = self._price(res.path, world, dyn, v0)
            timing["spot_selection_time"] += time.perf_counter() - t1
            if wait < 0:
                blocked_by_agents = True
                blocked_out.append(_Candidate(mode, int(self.lot.spot_ids[it]) if mode == PARK else -1, res.goal,
                                              res.path, math.inf, 0, True, hit))
                continue
            found.append(_Candidate(mode, int(self.lot.spot_ids[it]) if mode == PARK else -1, res.goal,
                                    stop_path or res.path, cost, wait, True if mode == PARK else bool(it[1]),
                                    wait_on_path=stop_path is not None))
            best = min(best, cost - bonus)
        found.sort(key=lambda c: c.cost - self._commitment_bonus(mode, c.spot_id))
        return found, blocked_by_agents

    def _commitment_bonus(self, mode: str, spot_id: int) -> float:
        """``decision.spot_commitment`` (extra; §V-D-1 takes the lowest c_park afresh at every search): the bonus a
        plan to the spot of the last parking plan gets, so that a search from a pose a few centimetres aside does not
        switch spots over a near tie; 0 for any other item or with the paper's 0."""
        m = self.settings.decision.spot_commitment
        if m <= 0 or mode != PARK:
            return 0.0
        return m if spot_id == getattr(self, "_committed_spot", -1) else 0.0

    def _adopt(self, cands: list[_Candidate], world: StaticWorld, dyn: DynamicObstacles, obs: Observation,
               timing: dict, require_dynamic: bool = True) -> _Plan | None:
        """Track the cheapest candidate into controls and verify; fall back to the next one."""
        c = self.settings.collision
        for cand in cands:
            t0 = time.perf_counter()
            traj = track(cand.path, self.settings.control, self.settings.vehicle.max_curvature, obs.ego_speed)
            timing["path_planning_time"] += time.perf_counter() - t0
            unwaited, wait_from = traj.states, 0
            if cand.wait_steps and cand.wait_on_path:  # mechanism c: stand at the path's stop
                at = stop_index(traj.controls[:, 0], traj.dt, cand.path.stops[0])
                st, ctl = insert_wait(traj.states, traj.controls, at, cand.wait_steps)
                traj, wait_from = Trajectory(ctl, st, traj.dt), at + 1
            elif cand.wait_steps:
                z = np.zeros((cand.wait_steps, 2))
                st = np.repeat(traj.states[:1], cand.wait_steps, axis=0)
                traj = Trajectory(np.concatenate([z, traj.controls]), np.concatenate([st, traj.states]), traj.dt)
            margins = start_relaxed_margins(traj.states, c)
            st = traj.states
            ok = world.free_xyc(st[:, 0], st[:, 1], np.cos(st[:, 2]), np.sin(st[:, 2]), margins).all()
            if ok and cand.mode == PARK:
                ok = self._parked_in(traj.states[-1], cand.goal, cand.spot_id, obs)
            if ok and (not require_dynamic or dyn.first_collision(traj.states) < 0):
                plan = _Plan(cand.mode, cand.spot_id, cand.goal, traj, cand.cost, margins, 0, cand.path.length,
                             wait_steps=int(cand.wait_steps), wait_from=wait_from)
                if cand.wait_steps:  # who it waits for: the first agent met if it went at once
                    plan.wait_cause = blocker_trace(dyn, unwaited if cand.wait_on_path
                                                    else traj.states[cand.wait_steps:], obs)
                return plan
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

    def _searcher(self, world: StaticWorld, ego: np.ndarray, timing: dict):
        t0 = time.perf_counter()
        heur = EgoHeuristic(world, ego, self.settings, self._distance_cache)  # same world and cell: same map
        timing["path_planning_time"] += time.perf_counter() - t0
        return heur, HybridAStar(world, ego, self.settings, heur)

    def _explore(self, ego, world, dyn, heur, astar, obs, t_end, stats, timing, blocked_out,
                 max_iterations: int | None = None, back_allowed: bool = True, behind: bool = True):
        """Front exploration points, then (if allowed) those behind. Returns (plan or None, some path blocked by
        predicted agents, the front had paths but all were blocked by predicted agents). ``behind=False``: front
        points only (the detour round, whose static world holds the standing agents: a front blocked by them is
        blocked by agents, so turning back waits as long as for moving ones)."""
        pts = []
        for pose, front, rid in self.exploration_points(ego):
            g = self._explore_goal(pose, world)
            if g is not None and math.hypot(g[0] - ego[0], g[1] - ego[1]) > 1.0:
                pts.append((g, front, rid))
        blocked_any = front_waits = False
        for group in (True, False):  # front points first; behind only if the front stays blocked
            items = [p for p in pts if p[1] == group]
            if group is False and ((front_waits and not back_allowed) or not behind):
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


def start_relaxed_margins(states: np.ndarray, collision) -> np.ndarray:
    """The static clearance each state of a plan keeps: 0 within ``start_relax_distance`` of arc length from its
    start (the ego may begin next to an obstacle), ``verify_margin`` after."""
    arc = np.cumsum(np.r_[0.0, np.hypot(*np.diff(states[:, :2], axis=0).T)])
    return np.where(arc < collision.start_relax_distance, 0.0, collision.verify_margin)

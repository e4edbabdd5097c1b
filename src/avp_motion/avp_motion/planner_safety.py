"""The safety extras beyond the paper's idle rule (§V-D-3 says u = 0), each a planner switch the protocols
turn off (docs/experiment.md, "Protocols"): ``evasive`` — when standing still is itself predicted to be hit,
drive the candidate that is hit latest or never; ``dynamic_as_static_fallback`` — when every plan was blocked by
predicted agents only, search once more with the agents that stand still as static obstacles (a detour round a
stopped car).

A part of :class:`avp_planner.core.decision.EgoPlanner` (split by job).
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from avp_motion.control import reference_trajectory, track
from avp_motion.planner_types import (
    EXPLORE,
    PARK,
    _Candidate,
    _Plan,
)
from avp_search.paths import Path


class SafetyMixin:
    """Methods of :class:`~avp_planner.core.decision.EgoPlanner`; see the module docstring."""

    def _evade(self, ego, world, dyn, obs, blocked_plans, timing) -> _Plan | None:
        """If standing still is predicted to be hit, drive whatever is hit latest (or never): the blocked
        plans of this step and short escape arcs (every curvature of the steering set, forward and reverse,
        2 to 8 m). Returns None when standing still is safe or nothing does better."""
        if dyn.empty:
            return None
        standing = dyn.first_collision(np.repeat(ego[None], dyn.horizon + 2, axis=0))
        limit = self.settings.decision.evasive_horizon  # only an imminent hit (0: any)
        if standing < 0 or (limit > 0 and standing * self.settings.control.dt > limit + 1e-9):
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
            plan.kind = "evasive"
        return plan

    def _creep(self, st) -> _Plan | None:
        """``deadlock_breaker`` (mechanism d): once the ego has stood ``stuck_time``, the blocked plan
        that meets the predictions latest, tracked at ``creep_speed``, if its next ``creep_check_time`` seconds meet
        no predicted agent (any hypothesis, margins as usual) and no static obstacle; None otherwise. Re-decided
        every step: the ego stops as soon as the check fails (braking from 0.5 m/s takes 0.25 s)."""
        d, c = self.settings.decision, self.settings.control
        if not d.deadlock_breaker or self._stuck_steps * c.dt < d.stuck_time - 1e-9 or not st.blocked_plans:
            return None
        slow = replace(c, v_max=d.creep_speed)
        n = int(round(d.creep_check_time / c.dt))
        for cand in sorted(st.blocked_plans, key=lambda p: -(p.first_hit if p.first_hit >= 0 else 10**9))[:3]:
            traj = track(cand.path, slow, self.settings.vehicle.max_curvature, st.obs.ego_speed)
            head = traj.states[: n + 1]
            m = self.settings.collision.verify_margin
            if not st.world.free(head[1:], m).all():
                continue
            hits = st.dyn.collision_steps(head)
            if len(hits) and hits[0] <= n:
                continue
            margins = np.full(len(traj.states), m)
            return _Plan(cand.mode, cand.spot_id, cand.goal, traj, math.inf, margins, 0, cand.path.length,
                         note=f"creeping: stood {self._stuck_steps * c.dt:.1f} s (deadlock_breaker)", kind="creep")
        return None

    def _detour(self, obs, b, ego, world, dyn, cands, ordered, t_end, stats, timing, blocked_plans, back_ok):
        """``dynamic_as_static_fallback``: park, else explore, with the standing agents' current footprints as
        static obstacles (small budget: ``fallback_time_cap``, ``fallback_max_iterations``); None if no plan."""
        d = self.settings.decision
        plan = None
        extra = self._agents_as_rects(obs)
        if len(extra):
            t_fb = min(t_end, time.perf_counter() + d.fallback_time_cap)
            it_fb = d.fallback_max_iterations
            world2 = self._static_world(obs, b, extra, base=world)
            heur2, astar2 = self._searcher(world2, ego, timing)
            if len(cands):
                found, _ = self._search_set(PARK, cands.tolist(), ego, world, dyn, heur2, astar2,
                                            obs.ego_speed, t_fb, stats, timing, blocked_plans, it_fb, ordered)
                plan = self._adopt(found, world, dyn, obs, timing)
            if plan is None:
                plan, _, _ = self._explore(ego, world, dyn, heur2, astar2, obs, t_fb, stats, timing,
                                           blocked_plans, it_fb, back_ok,
                                           behind=back_ok or not d.detour_waits_to_turn_back)
            if plan is not None:
                stats["around_agents"] = True
        if plan is not None:
            plan.kind = "detour"
        return plan

"""The ego's decision of paper §V-D ("Final Trajectory Planning"): park, else explore, else idle (ROS-free).

At each step t, :meth:`EgoPlanner.decide` receives the observation (§III-A), the belief map b_t (§V-B; or
``None``) and the predicted trajectories (§V-C), and returns a :class:`Decision` with the command u_0,t.

**Beliefs.** With ``beliefs=None`` the planner keeps "beliefs from observation only" (the first update of
§V-B without the intention model): b = 0.5 initially; observed vacant -> 0, observed occupied -> 1,
otherwise kept.

**Static world** (:mod:`~avp_collision.static`): lot boundary, spots with b >= β as full spot
rectangles, observed static vehicles. **Dynamic obstacles**: the given predictions; an observed dynamic
vehicle or pedestrian without any prediction gets a constant-velocity one (``fallback_prediction``; §V-C uses
constant velocity for pedestrians), so that the planner stays safe when run without a prediction module.

**Parking (§V-D-1).** Candidates I_can,0 = {i in I_vac,t : b_t,i <= δ}. Goals: the ego centred in the spot with
the spot heading or its opposite (both seeds of one Hybrid A* search). Candidates are searched in order of
a lower bound of c_park (from the exact obstacle-free Reeds-Shepp length and the 2-D obstacle-aware
distance), and the loop stops when the next lower bound is not below the best feasible cost found
(branch and bound: the result is the one of planning every candidate, at a fraction of the cost). A path is
time-indexed with its speed profile (:mod:`~avp_motion.control`) and kept if its footprints avoid
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
current gap (:class:`~avp_collision.static.DynamicObstacles`), so the ego is not frozen next to it;
and if standing still is itself predicted to be hit (``evasive``), the ego drives the candidate that is hit
latest or never: a blocked plan of this step or a short escape arc (forward/reverse, 2-8 m).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from avp_collision.static import DynamicObstacles, StaticWorld
from avp_motion.belief_window import BeliefWindow
from avp_motion.drift_steer import follows, steer_control
from avp_motion.making_way import MakeWayMixin
from avp_motion.planner_candidates import CandidatesMixin
from avp_motion.planner_inputs import InputsMixin
from avp_motion.planner_safety import SafetyMixin
from avp_motion.planner_search import SearchMixin
from avp_motion.planner_types import (
    CONTAINED_MARGIN,
    EXPLORE,
    EXPLORE_BACK_AFTER,
    IDLE,
    PARK,
    SEARCH_CACHE,
    STILL_SPEED,
    WORLD_CACHE_SIZE,
    Decision,
    _Plan,
    _Step,
)
from avp_motion.reanchor import HEADING_TOLERANCE, deviation, follow_tolerance, reanchored, remaining_length
from avp_motion.settings import PlannerSettings
from avp_motion.trace import blocked_poses, idle_cause
from avp_motion.yielding import ReactionEvidence
from avp_planner.core.ego_yield import EgoYieldMixin
from avp_planner.core.spot_selection import SelectionContext, make_spot_selector
from avp_search.hybrid_astar import PlanResult
from avp_world.lot import LotMap
from avp_world.types import Observation, PredictedTrajectory, priority_from_probabilities

__all__ = ["EgoPlanner", "Decision", "priority_from_probabilities", "PARK", "EXPLORE", "IDLE", "STILL_SPEED",
           "EXPLORE_BACK_AFTER", "WORLD_CACHE_SIZE", "SEARCH_CACHE", "CONTAINED_MARGIN"]


class EgoPlanner(InputsMixin, CandidatesMixin, SearchMixin, SafetyMixin, MakeWayMixin, EgoYieldMixin):
    """§V-D decision logic; see the module docstring. One instance per episode (or call :meth:`reset`).

    Args:
        lot: the lot map (§II-A).
        settings: planner settings (validated).
    """

    def __init__(self, lot: LotMap, settings: PlannerSettings = PlannerSettings()):
        self.lot = lot
        self.settings = settings.validate()
        self.spot_selector = make_spot_selector(self.settings.decision.spot_selector, lot)
        from avp_search.hybrid_astar import rs_length_table

        s = settings.search
        rs_length_table(round(settings.plan_radius, 9), s.rs_table_resolution, s.rs_table_extent, s.heading_bins)
        self.reset()

    def reset(self) -> None:
        """Forget the internal beliefs and the plan being executed."""
        self.beliefs = np.full(self.lot.n_spots, 0.5)
        self._plan: _Plan | None = None
        self._world_cache: dict[tuple, StaticWorld] = {}
        self._spots_cache: dict[tuple, StaticWorld] = {}  # the believed-occupied spots' worlds (_spots_world)
        self._merge_cache: dict[tuple, tuple] = {}  # the believed-occupied spots merged (merge_rects_after)
        self._distance_cache: dict[tuple, tuple] = {}  # the heuristic's 2-D distance maps by (world, start cell)
        self._last_park_attempt: tuple | None = None
        self._park_attempt_step = -(10**9)
        self._front_blocked_step: int | None = None  # since when the road ahead is blocked by agents only
        self._idle_until = -(10**9)  # idle_replan_steps: no new search before this step after an idle decision
        self._searches: dict[tuple, PlanResult] = {}  # see SEARCH_CACHE
        self._last_cause: dict = {"cause": "unknown"}  # why the last idle decision was idle (decision trace)
        self._stuck_steps = 0  # consecutive steps stood idle or waiting (creep steps keep the count)
        self._evidence = ReactionEvidence(self.settings.decision.yield_lookahead,
                                          self.settings.collision.reactive_decel)  # collision.reactive_evidence
        self._told_reacting: frozenset = frozenset()  # reactive_evidence: told (tell_reacting)
        self._make_way_for: list = []  # make_way: the cars (id, where they stood) the ego stands aside for ...
        self._make_way_until = -1  # ... until this step at most
        self._make_way_retry = -(10**9)  # no new search for a way out before this step
        self._ped_heading: dict[int, float] = {}  # make_way: the direction each pedestrian last walked in
        self._wanted = np.zeros((0, 3))  # the plan the last idle decision was blocked on (Decision.wanted)
        self._committed_spot = -1  # decision.spot_commitment: the spot the last parking plan aimed at
        self._belief_window = BeliefWindow(self.lot.n_spots, self.settings.decision.belief_window)

    def tell_reacting(self, keys) -> None:
        """With ``collision.reactive_evidence: told``: the agents that stop for the ego (keys (is a pedestrian,
        id)), as the caller knows them; the rest are checked as §V-D-1 does. Only a reference bound knows this
        (``avp_episode.oracle``: the simulator's n_pass > 0); it holds until told again."""
        self._told_reacting = frozenset((bool(p), int(i)) for p, i in keys)

    def decide(self, obs: Observation, beliefs: np.ndarray | None = None,
               predictions: Sequence[PredictedTrajectory] = (), spot_priority: Sequence[int] | None = None,
               time_budget: float | None = None) -> Decision:
        """One decision step of §V-D (see the module docstring).

        ``spot_priority`` (spot ids, most wanted first; the "Implicit" method of §VI-B-3): the candidate spots
        are tried in that order — candidates not listed last, nearest first — and the first one with a safe
        plan is taken instead of the lowest c_park.

        ``time_budget`` (s, wall clock): no search starts or runs past it, as ``decision.decision_time_cap``
        (the smaller holds); the planner node passes what is left of its real-time deadline
        (``realtime_decision_deadline``). None: the cap only.
        """
        dec = self._decide(obs, beliefs, predictions, spot_priority, time_budget)
        mode = dec.trace.get("mode", dec.mode)  # how long the ego has stood (deadlock_breaker's clock)
        self._stuck_steps = (self._stuck_steps + 1 if mode in ("idle", "wait_and_go")
                             else self._stuck_steps if mode == "creep" else 0)
        return dec

    def _decide(self, obs: Observation, beliefs: np.ndarray | None, predictions, spot_priority,
                time_budget: float | None) -> Decision:
        t_start = time.perf_counter()
        timing = {"spot_selection_time": 0.0, "path_planning_time": 0.0, "total": 0.0}
        predictions = list(predictions or ())
        bad = self._check_inputs(obs, beliefs, predictions)
        if bad:
            self._plan = None
            return self._finish(Decision(IDLE, reason=bad, trace={"mode": IDLE, "cause": "invalid_input"}), timing,
                                t_start)
        if self.settings.collision.reactive_steps > 0 and self.settings.collision.reactive_evidence in ("agent", "lot"):
            self._evidence.update(obs)
        if self.settings.decision.make_way:
            self._remember_headings(obs)
        if self._plan is None and obs.step < self._idle_until:  # stay put until the next idle re-plan (§V-D-3)
            if beliefs is None:
                self.update_beliefs(obs)
            return self._finish(Decision(IDLE, reason=f"waiting: re-plan at step {self._idle_until} "
                                                      "(idle_replan_steps)", poses=np.asarray(obs.ego_pose,
                                                                                             float)[None].copy(),
                                         trace={"mode": IDLE, **self._last_cause}, wanted=self._wanted.copy()),
                                timing, t_start)
        aside = self._aside_decision(obs, beliefs)  # make_way: standing aside until the agent has gone
        if aside is not None:
            return self._finish(aside, timing, t_start)
        st = self._step_context(obs, beliefs, predictions, spot_priority, timing, t_start, time_budget)
        done, keep_explore = self._follow_current(st)
        if done is None:
            done = self._try_parking(st, keep_explore)
        if done is None:
            done = self._try_exploring(st, keep_explore)
        return done if done is not None else self._go_idle(st)

    def _step_context(self, obs: Observation, beliefs: np.ndarray | None, predictions: list[PredictedTrajectory],
                      spot_priority: Sequence[int] | None, timing: dict, t_start: float,
                      time_budget: float | None = None) -> _Step:
        """Beliefs, static world, predicted obstacles and candidate spots of this step (spot-selection time)."""
        b = self.update_beliefs(obs).copy() if beliefs is None else np.asarray(beliefs, dtype=float)
        if self.settings.decision.belief_window > 1:  # extra: a vacant spot's belief over its last steps
            b = self._belief_window.read(b, self.vacant_rows(obs))
        ego = np.asarray(obs.ego_pose, dtype=float)
        t0 = time.perf_counter()
        world = self._static_world(obs, b)
        dyn = self._dynamic(obs, predictions)
        sel = self.spot_selector.select(self.candidate_spots(obs, b), SelectionContext(obs, b, ego, spot_priority))
        cands, ordered = np.asarray(sel.rows, dtype=np.int64).reshape(-1), bool(sel.first_feasible)
        timing["spot_selection_time"] += time.perf_counter() - t0
        return _Step(obs=obs, b=b, ego=ego, world=world, dyn=dyn, cands=cands, ordered=ordered, timing=timing,
                     t_start=t_start, t_end=t_start + min(self.settings.decision.decision_time_cap,
                                                          math.inf if time_budget is None else time_budget))

    def _follow_current(self, st: _Step) -> tuple[Decision | None, _Plan | None]:
        """1. The plan being executed: parked at its end, still valid (go on), or dropped. Returns (the decision
        if this step ends here, an exploration plan to keep unless parking succeeds)."""
        p, ego = self._plan, st.ego
        if p is not None and p.mode == PARK and p.index >= len(p.traj.controls):
            if math.hypot(*(p.traj.states[-1][:2] - ego[:2])) <= self.settings.decision.replan_pose_tolerance:
                return self._finish(Decision(IDLE, spot_id=p.spot_id, goal=p.goal.copy(), poses=ego[None].copy(),
                                             n_candidates=len(st.cands), reason="parked",
                                             trace={"mode": "parked"}), st.timing, st.t_start), None
        if self._plan is None:
            return None, None
        self._reanchor(self._plan, ego, st.obs)
        ok, st.why = self._still_valid(self._plan, ego, st.world, st.dyn)
        if ok and (self._plan.mode == PARK or self._plan.kind == "make_way"):
            return self._finish(self._execute(self._plan, len(st.cands), "executing"), st.timing, st.t_start), None
        if ok:
            return None, self._plan
        self._plan = None
        return None, None

    def _try_parking(self, st: _Step, keep_explore: _Plan | None) -> Decision | None:
        """2. Parking (§V-D-1): search the candidate spots unless nothing changed since the last try while an
        exploration plan runs (retried at least every ``park_retry_steps``)."""
        d, obs, ego = self.settings.decision, st.obs, st.ego
        attempt_key = (st.world.key, tuple(st.cands.tolist()), tuple(np.floor(ego[:2]).astype(int).tolist()))
        retry = (keep_explore is None or attempt_key != self._last_park_attempt
                 or obs.step - self._park_attempt_step >= d.park_retry_steps)
        if not (len(st.cands) and retry):
            return None
        self._last_park_attempt, self._park_attempt_step = attempt_key, obs.step
        st.heur, st.astar = self._searcher(st.world, ego, st.timing)
        found, st.blocked = self._search_set(PARK, st.cands.tolist(), ego, st.world, st.dyn, st.heur, st.astar,
                                             obs.ego_speed, st.t_end, st.stats, st.timing, st.blocked_plans,
                                             first_feasible=st.ordered)
        plan = self._adopt(found, st.world, st.dyn, obs, st.timing)
        if plan is None:
            return None
        self._plan = plan
        return self._finish(self._execute(plan, len(st.cands), "new parking plan", True), st.timing, st.t_start,
                            st.stats)

    def _try_exploring(self, st: _Step, keep_explore: _Plan | None) -> Decision | None:
        """3. Exploration (§V-D-2): keep the running exploration plan, else search the exploration points (points
        behind only after the front has been blocked EXPLORE_BACK_AFTER s), else the detour extra."""
        if keep_explore is not None:
            return self._finish(self._execute(keep_explore, len(st.cands), "exploring"), st.timing, st.t_start,
                                st.stats)
        obs, ego = st.obs, st.ego
        if st.heur is None:
            st.heur, st.astar = self._searcher(st.world, ego, st.timing)
        back_ok = (self._front_blocked_step is not None
                   and (obs.step - self._front_blocked_step) * self.settings.control.dt >= EXPLORE_BACK_AFTER - 1e-9)
        plan, blocked_e, front_waits = self._explore(ego, st.world, st.dyn, st.heur, st.astar, obs, st.t_end,
                                                     st.stats, st.timing, st.blocked_plans, None, back_ok)
        if front_waits:
            if self._front_blocked_step is None:
                self._front_blocked_step = obs.step
        else:
            self._front_blocked_step = None
        st.blocked |= blocked_e
        if plan is None and st.blocked and self.settings.decision.dynamic_as_static_fallback:
            plan = self._detour(obs, st.b, ego, st.world, st.dyn, st.cands, st.ordered, st.t_end, st.stats,
                                st.timing, st.blocked_plans, back_ok)
        if plan is None:
            return None
        self._plan = plan
        what = "new parking plan around agents" if plan.mode == PARK else "new exploration plan"
        return self._finish(self._execute(plan, len(st.cands), what, True), st.timing, st.t_start, st.stats)

    def _go_idle(self, st: _Step) -> Decision:
        """4. Idle (§V-D-3), unless standing still is itself predicted to be hit: then the blocked plan that meets
        the predicted agents latest (later than standing still) is driven, re-checked every step (extra)."""
        d, ego = self.settings.decision, st.ego
        if d.evasive:
            plan = self._evade(ego, st.world, st.dyn, st.obs, st.blocked_plans, st.timing)
            if plan is not None:
                self._plan = plan
                st.stats["evasive"] = True
                return self._finish(self._execute(plan, len(st.cands), plan.note, True), st.timing, st.t_start,
                                    st.stats)
        plan, how = self._yield_to_ego(st), "ego_yield"
        if plan is None:
            plan, how = self._make_way(st), "make_way"
        if plan is not None:  # ego_yield, make_way: out of the way of a car waiting for the ego, then stand aside
            self._plan = plan
            st.stats[how] = True
            return self._finish(self._execute(plan, len(st.cands), plan.note, True), st.timing, st.t_start,
                                st.stats)
        plan = self._creep(st)
        if plan is not None:  # deadlock_breaker: one step of the creep, re-decided next step
            return self._finish(self._execute(plan, len(st.cands), plan.note, True), st.timing, st.t_start, st.stats)
        reason = "no safe parking or exploration plan" + (f" ({st.why})" if st.why else "")
        self._idle_until = st.obs.step + d.idle_replan_steps
        wanted = blocked_poses(st, self.settings.control)
        self._last_cause = idle_cause(st, self.settings.control, wanted)
        self._wanted = np.zeros((0, 3)) if wanted is None else np.asarray(wanted, dtype=float)
        return self._finish(Decision(IDLE, n_candidates=len(st.cands), reason=reason, poses=ego[None].copy(),
                                     trace={"mode": IDLE, **self._last_cause}, wanted=self._wanted.copy()),
                            st.timing, st.t_start, st.stats)

    def _reanchor(self, plan: _Plan, ego: np.ndarray, obs: Observation) -> None:
        """``decision.replan_pose_sigmas``: a plan the pose estimate has drifted off, within the localiser's
        tolerance, moved onto the estimate (``decision.pose_drift`` reanchor, :mod:`avp_motion.reanchor`) or kept and
        marked to be steered back to (steer, :mod:`avp_motion.drift_steer`); nothing for exact sensing or k = 0."""
        d, k = self.settings.decision, plan.index
        plan.steer = None
        if d.replan_pose_sigmas <= 0 or obs.ego_covariance is None or k >= len(plan.traj.controls):
            return
        if plan.mode == PARK and remaining_length(plan.traj.controls[k:], plan.traj.dt) < d.replan_pose_near:
            return  # near the spot the paper's re-check aims at it again, from a short lever arm
        if d.pose_drift == "steer":  # kept in the lot's frame, steered back to (avp_motion.drift_steer)
            tol = follow_tolerance(obs.ego_covariance, d.replan_pose_sigmas, d.replan_pose_tolerance)
            if follows(plan.traj.states, k, ego, tol, self.settings.control.lateral_correction_length):
                plan.steer = np.array(ego[:3], dtype=float)
            return
        off, off_th = deviation(plan.traj.states[k], ego)
        if off <= d.replan_pose_tolerance and off_th <= HEADING_TOLERANCE:
            return  # on the plan: as the paper
        tol, tol_th = follow_tolerance(obs.ego_covariance, d.replan_pose_sigmas, d.replan_pose_tolerance)
        if off <= tol and off_th <= tol_th:
            plan.traj = replace(plan.traj, states=reanchored(plan.traj.states, k, ego))

    def _still_valid(self, plan: _Plan, ego: np.ndarray, world: StaticWorld, dyn: DynamicObstacles) -> tuple[bool, str]:
        d = self.settings.decision
        k = plan.index
        if k >= len(plan.traj.controls):
            return False, "plan finished"
        if plan.steer is None:  # a plan being steered back to was checked against its tolerance (_reanchor)
            off, off_th = deviation(plan.traj.states[k], ego)
            if off > d.replan_pose_tolerance or off_th > HEADING_TOLERANCE:
                return False, "ego off the plan"
        rest = plan.traj.states[k:]
        r1 = rest[1:]
        if not world.free_xyc(r1[:, 0], r1[:, 1], np.cos(r1[:, 2]), np.sin(r1[:, 2]), plan.margins[k + 1:]).all():
            return False, "static obstacle on the plan"
        hit = dyn.first_collision(rest)
        window = d.keep_plan_window  # a plan being driven is dropped only for a meeting within it
        if hit >= 0 and (window <= 0 or hit * self.settings.control.dt <= window + 1e-9):
            return False, "predicted agent on the plan"
        if plan.mode == EXPLORE and plan.kind != "make_way":
            left = np.abs(plan.traj.controls[k:, 0]).sum() * plan.traj.dt
            if left < d.explore_replan_distance:
                return False, "exploration plan nearly done"
        return True, ""

    def _execute(self, plan: _Plan, n_cand: int, reason: str, new: bool = False) -> Decision:
        if new and plan.mode == PARK:
            self._committed_spot = plan.spot_id
        k = plan.index
        u = plan.traj.controls[k]
        if plan.steer is not None:  # decision.pose_drift steer: the estimate steered back onto the plan
            c = self.settings.control
            u = steer_control(plan.traj.states, plan.traj.controls, k, plan.steer, c.dt,
                              c.lateral_correction_length, self.settings.vehicle.max_curvature)
        plan.index += 1
        trace = ({"mode": "wait_and_go", **plan.wait_cause} if plan.wait_from <= k < plan.wait_from + plan.wait_steps
                 else {"mode": plan.kind or plan.mode})
        return Decision(plan.mode, spot_id=plan.spot_id, goal=plan.goal.copy(), poses=plan.traj.states[k:].copy(),
                        controls=plan.traj.controls[k:].copy(), command=(float(u[0]), float(u[1])),
                        n_candidates=n_cand, reason=reason, cost=plan.cost, replanned=new, trace=trace)

    @staticmethod
    def _finish(dec: Decision, timing: dict, t_start: float, stats: dict | None = None) -> Decision:
        timing["total"] = time.perf_counter() - t_start
        dec.timings = timing
        if stats:
            dec.stats.update(stats)
        return dec

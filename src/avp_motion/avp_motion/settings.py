"""Every knob of the ego planner of §V-D (ROS-free), as frozen dataclasses.

The collision and search settings are the shared search core's (:mod:`avp_search.settings`, re-exported here);
tracking, cost and decision settings are the planner's own. Where a knob is a symbol of the paper it is named in
the comment (β, δ, Δt, R_min, the sensing radius of Q_0 ...). Defaults are the values the tests and
``bench/bench_planner.py`` use.

Units: metres, seconds, radians.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from avp_search.settings import CollisionSettings, SearchConfig, SearchSettings

POSE_DRIFT_RESPONSES = ("reanchor", "steer")  # decision.pose_drift

__all__ = ["CollisionSettings", "SearchSettings", "SearchConfig", "ControlSettings", "CostSettings",
           "DecisionSettings", "PlannerSettings", "DEFAULT_SETTINGS"]


@dataclass(frozen=True)
class ControlSettings:
    """Path -> per-step controls (v, ω) of eq. (1) at Δt."""

    dt: float = 0.1  # Δt (§II-B)
    v_max: float = 2.0  # planning speed limit (ParkSim/Nawaz 2 m/s)
    a_max: float = 2.0  # |dv/dt| limit of the speed profile
    lateral_correction_length: float = 1.0  # the tracker steers a lateral error away over this distance


@dataclass(frozen=True)
class CostSettings:
    """c_park of a plan, after Nawaz et al. (see :mod:`avp_planner.core.decision`)."""

    w_length: float = 1.0  # per metre of path
    w_reverse: float = 1.0  # per metre driven in reverse
    w_switch: float = 3.0  # per change of driving direction
    w_time: float = 0.5  # per second of plan, waiting included
    w_static: float = 1.0  # proximity to static obstacles: sum exp(-3 clearance) ds
    w_dynamic: float = 1.0  # proximity to predicted agents: sum exp(-2 clearance) dt


@dataclass(frozen=True)
class DecisionSettings:
    """§V-D decision logic (parking, exploration, idling)."""

    belief_threshold: float = 0.5  # β (§V-B): spots with belief >= β are drawn as occupied
    candidate_threshold: float = 0.3  # δ (§V-D): candidate spots have belief <= δ
    sensing_radius: float = 11.5  # radius of the disc Q_0 (§VI-A); exploration points lie on its boundary
    explore_lane_offset: float = 1.75  # exploration goal shifted right of the centre line (0 = paper literal)
    explore_goal_slide: tuple[float, ...] = (0.0, -1.5, -3.0)  # try the point moved back along the road
    explore_max_length: float = 30.0  # longer exploration paths do not count: that way is "blocked" (§V-D-2)
    explore_replan_distance: float = 4.0  # replan exploration when less than this is left of the plan
    max_candidates_planned: int = 40  # cap on spots searched per step (branch and bound prunes first)
    branch_and_bound: bool = True  # skip candidates whose lower bound of c is not below the best plan found
    max_wait: float = 3.0  # wait-and-go: plans may start after waiting up to this long (Nawaz)
    wait_step: float = 0.5
    replan_pose_tolerance: float = 0.05  # ego further than this from the plan's state => replan
    # extra (beyond §V-D's re-check, which drops a plan the ego is off): under a localiser's estimate, a driven plan
    # the estimate has drifted off by less than replan_pose_sigmas standard deviations of its covariance is moved
    # onto the estimate and kept (avp_motion.reanchor); 0 = the paper. Exact sensing reports no covariance: no change
    replan_pose_sigmas: float = 0.0  # re-anchor a driven plan within this many localisation std devs (0: the paper)
    replan_pose_near: float = 0.0  # m: a parking plan with less path left is not re-anchored (0: to the end)
    # within those std devs: reanchor = the plan moved onto the estimate; steer = the plan kept in the lot's frame and
    # the estimate steered back onto it (avp_motion.drift_steer)
    pose_drift: str = "reanchor"  # what replan_pose_sigmas does with a drifted-off plan: reanchor or steer
    # extra (§V-D-1 takes the lowest c_park afresh at every search): a plan to the spot the last parking plan aimed at
    # is priced spot_commitment lower, so a search from a pose a few cm aside does not switch spots over a near tie
    spot_commitment: float = 0.0  # c_park bonus of the spot the last parking plan aimed at (0: the paper)
    # extra (§V-D-1 reads this step's b_t): an observed vacant spot's belief read as the lower median of its eq. (8)
    # values over its last belief_window vacant steps (avp_motion.belief_window), so a one-step spike is not seen
    belief_window: int = 1  # steps of an observed vacant spot's belief the planner reads (1: this step's, the paper)
    fallback_prediction: str = "constant_velocity"  # for observed agents without a prediction: | "static" | "none"
    fallback_horizon: float = 3.0  # seconds of the fallback constant-velocity prediction
    dynamic_as_static_fallback: bool = True  # replan around current agent footprints if all plans are blocked
    # in that round a road ahead blocked by standing agents counts as blocked by agents (§V-D-2 "only ... if the road
    # ahead of it stays blocked"): exploring behind waits as in the first round; false: at once (as before v0.2.0)
    detour_waits_to_turn_back: bool = True  # that round turns back only after the front stayed blocked 3 s (§V-D-2)
    fallback_time_cap: float = 0.05  # seconds for that second round of searches
    fallback_max_iterations: int = 300  # node pops per search in that round
    evasive: bool = True  # if standing still is predicted to be hit, drive the plan that is hit latest
    evasive_horizon: float = 0.0  # evade only a hit of the standing ego within this many s; 0 = any predicted
    decision_time_cap: float = 0.4  # seconds of searching per decision step (remaining candidates skipped)
    park_retry_steps: int = 5  # while exploring, parking is re-tried at least this often (and on any change)
    idle_replan_steps: int = 1  # after an idle decision (no safe plan) search again only this many steps later
    spot_selector: str = "auto"  # §V-D-1 spot choice: auto, c_park, ego_intention or a plugin (avp.spot_selectors)
    # mechanism a (beyond §V-D, which predicts every car along its intentions): a car standing or braking
    # with the ego ahead of it within yield_lookahead is predicted to keep standing — the reactive agents of §III-B
    # stop for the ego — its footprint grown forward by yield_margin (it may roll on while braking); false = the paper
    assume_yielding: bool = False  # mechanism a: a car standing/braking with the ego ahead keeps standing (§V-C: no)
    yield_lookahead: float = 10.0  # m ahead of the car (its front) in which the ego counts as what it stops for
    yield_margin: float = 1.0  # m: braking margin added in front of a car assumed to yield
    # mechanism d (beyond §V-D-3 "the ego would stay put"): after stuck_time s without moving, creep along
    # the blocked plan that meets the predictions latest at creep_speed, each step only while its next
    # creep_check_time s meet no predicted agent (every hypothesis) and no static obstacle; false = the paper
    deadlock_breaker: bool = False  # mechanism d: creep along the best blocked plan after stuck_time (§V-D-3: no)
    stuck_time: float = 3.0  # s stopped (idle or waiting) before creeping
    creep_speed: float = 0.5  # m/s
    creep_check_time: float = 2.0  # s of the creep checked hard against every hypothesis, each step
    # mechanism e (beyond §V-D-3 "the ego would stay put"): after make_way_after s without moving, if a
    # standing car's corridor (its footprint swept make_way_reach m along its travel) holds the ego, drive the shortest
    # short manoeuvre that ends clear of that corridor swept make_way_clear m and meets no prediction, then stand
    # there until that car has moved 1 m or make_way_hold s have passed (avp_motion.making_way)
    make_way: bool = False  # mechanism e: step out of the way of an agent waiting for the ego (§V-D-3: no)
    make_way_after: float = 2.0  # s stopped (idle or waiting) before making way
    make_way_reach: float = 3.0  # m of a standing car's path in which the ego counts as in its way
    make_way_clear: float = 8.0  # m of that path the ego's end pose must be clear of
    make_way_hold: float = 5.0  # s at most to stand aside after the manoeuvre
    # ego_yield (beyond §V-D-3 "the ego would stay put"; a fleet only: it reads the beacons other egos send, a message
    # between egos): after ego_yield_after s without moving, if an ego with the right of way stands waiting with this
    # ego on the first ego_yield_clear m of the path it announced, drive the shortest short manoeuvre that ends clear
    # of that path, then stand aside until that car has moved 1 m or ego_yield_hold s have passed
    # (avp_planner.core.ego_yield)
    ego_yield: bool = True  # give way to an ego with the right of way that waits for this one (fleets; §V-D-3: no)
    ego_yield_after: float = 2.0  # s stopped (idle or waiting) before giving way
    ego_yield_clear: float = 10.0  # m of the announced path the ego must end clear of
    ego_yield_hold: float = 5.0  # s at most to stand aside after the manoeuvre
    # debouncing (beyond §V-D's re-check of the whole plan against every prediction at every step): a plan
    # already being driven is dropped only when a predicted meeting comes within keep_plan_window s; a later one is
    # tolerated and re-checked next step (a new plan must still meet nothing); 0 = the paper
    keep_plan_window: float = 0.0  # s of the driven plan that must stay clear to keep it (0: all of it)
    # mechanism c (beyond §V-D-1's wait before starting, after Nawaz et al.): when every start wait fails,
    # stop on the path wait_stop_offsets m short of the first meeting and wait there 0 .. max_wait
    wait_anywhere: bool = False  # mechanism c: wait at a stop on the path, not only before starting (§V-D-1: no)
    wait_stop_offsets: tuple[float, ...] = (1.0, 2.5, 4.0)  # m of arc length short of the first meeting


@dataclass(frozen=True)
class PlannerSettings(SearchConfig):
    """All settings of :class:`~avp_planner.core.decision.EgoPlanner`: the search core's (vehicle, collision,
    search; :class:`~avp_search.settings.SearchConfig`) and the planner's own (control, cost, decision)."""

    control: ControlSettings = field(default_factory=ControlSettings)
    cost: CostSettings = field(default_factory=CostSettings)
    decision: DecisionSettings = field(default_factory=DecisionSettings)

    def validate(self) -> PlannerSettings:
        """Raise ValueError naming the first bad field; returns ``self``."""
        k, d = self.control, self.decision
        checks = [
            *self.search_checks(),
            ("control.dt", k.dt > 0),
            ("control.v_max", 0 < k.v_max <= self.vehicle.max_speed),
            ("control.a_max", k.a_max > 0),
            ("decision.belief_threshold", 0.0 <= d.belief_threshold <= 1.0),
            ("decision.candidate_threshold", 0.0 <= d.candidate_threshold < d.belief_threshold),
            ("decision.sensing_radius", d.sensing_radius > 0),
            ("decision.wait_step", d.wait_step > 0 and d.max_wait >= 0),
            ("decision.idle_replan_steps", d.idle_replan_steps >= 1),
            ("decision.fallback_prediction", d.fallback_prediction in ("constant_velocity", "static", "none")),
            ("decision.yield_lookahead", d.yield_lookahead >= 0),
            ("decision.stuck_time", d.stuck_time >= 0),
            ("decision.evasive_horizon", d.evasive_horizon >= 0),
            ("decision.creep_speed", 0 < d.creep_speed <= k.v_max),
            ("decision.creep_check_time", d.creep_check_time > 0),
            ("decision.yield_margin", d.yield_margin >= 0),
            ("decision.make_way_after", d.make_way_after >= 0),
            ("decision.keep_plan_window", d.keep_plan_window >= 0),
            ("decision.replan_pose_sigmas", d.replan_pose_sigmas >= 0),
            ("decision.replan_pose_near", d.replan_pose_near >= 0),
            ("decision.pose_drift", d.pose_drift in POSE_DRIFT_RESPONSES),
            ("decision.spot_commitment", d.spot_commitment >= 0),
            ("decision.belief_window", 1 <= d.belief_window <= 100),
            ("decision.make_way_reach", d.make_way_reach > 0),
            ("decision.make_way_clear", d.make_way_clear >= d.make_way_reach),
            ("decision.make_way_hold", d.make_way_hold >= 0),
            ("decision.ego_yield_after", d.ego_yield_after >= 0),
            ("decision.ego_yield_clear", d.ego_yield_clear > 0),
            ("decision.ego_yield_hold", d.ego_yield_hold >= 0),
            ("decision.wait_stop_offsets", all(o > 0 for o in d.wait_stop_offsets)),
            ("collision.commit_horizon", self.collision.commit_horizon >= 0),
            ("collision.risk_bound", 0.0 <= self.collision.risk_bound <= 1.0),
        ]
        for name, ok in checks:
            if not ok:
                raise ValueError(f"PlannerSettings.{name}: invalid value")
        return self


DEFAULT_SETTINGS = PlannerSettings()

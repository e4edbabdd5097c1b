"""Every knob of the ego planner of §V-D (ROS-free), as frozen dataclasses.

Where a knob is a symbol of the paper it is named in the comment (β, δ, Δt, R_min, the sensing radius of
Q_0 ...); the rest are the usual Hybrid A* settings (see docs and
``shared/reference/nawaz-occupancy-and-hybrid-astar-facts.md`` for the values used by Nawaz et al., Nav2 and
Autoware). Defaults are the values the tests and ``bench/bench_planner.py`` use.

Units: metres, seconds, radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from avp_world.vehicle import VehicleSpec


@dataclass(frozen=True)
class CollisionSettings:
    """Static world (occupancy grid + EDT) and footprint checks (§V-D: V_0,τ ⊆ L, V_0,τ ∩ S_i = ∅ for b ≥ β)."""

    grid_resolution: float = 0.1  # occupancy grid / Euclidean distance transform cell size
    n_discs: int = 4  # covering discs of the footprint used by the conservative EDT pre-check
    footprint_margin: float = 0.15  # clearance every searched sample keeps to static obstacles
    verify_margin: float = 0.05  # clearance the executed eq. (1) states keep to static obstacles
    start_relax_distance: float = 0.6  # arc length near the ego's current pose checked with verify_margin only
    vehicle_margin: float = 0.3  # clearance to predicted vehicle footprints (§V-D, time-indexed)
    pedestrian_margin: float = 0.4  # clearance to predicted pedestrian discs
    keep_current_gap: bool = True  # extra: an agent already nearer than the margin need only keep its gap (§V-D: no)
    beyond_horizon: str = "hold"  # a prediction after its last pose: "hold" it there | "release" (no obstacle)


@dataclass(frozen=True)
class SearchSettings:
    """Hybrid A* (§V-D, "the Hybrid A* implementation from [Nawaz]"), searched from the goal to the ego."""

    xy_resolution: float = 0.5  # closed-set cell size in x and y
    heading_bins: int = 72  # closed-set heading bins (5 deg)
    primitive_length: float = 1.6  # arc length of one motion primitive
    sample_step: float = 0.2  # spacing of collision-checked samples along primitives and Reeds-Shepp shots
    steering_fractions: tuple[float, ...] = (-1.0, -0.5, 0.0, 0.5, 1.0)  # curvature / kappa_plan
    curvature_reserve: float = 1.1  # plan with R_plan = 1.1 R_min: 10 % curvature left for the tracker
    reverse_penalty: float = 1.0  # extra cost per metre driven in reverse
    steer_penalty: float = 0.2  # extra cost per metre times |kappa| / kappa_plan
    steer_change_penalty: float = 0.3  # cost per change of curvature, times |d kappa| / kappa_plan
    switch_penalty: float = 4.0  # cost per change of driving direction (cusp)
    heuristic_weight: float = 2.5  # weighted A*: f = g + w h (w > 1 trades optimality for speed)
    heuristic_resolution: float = 1.0  # cell of the obstacle-aware 2-D Dijkstra heuristic
    rs_table_resolution: float = 0.5  # xy cell of the Reeds-Shepp length look-up table
    rs_table_extent: float = 15.0  # |x|, |y| covered by the table (Euclidean distance beyond)
    analytic_every: int = 3  # try a Reeds-Shepp shot every N pops (and on every pop when near)
    analytic_near: float = 8.0  # "near": heuristic below this distance
    analytic_detour: float = 1.3  # no shot when the 2-D distance exceeds this times the straight line
    analytic_candidates: int = 1  # Reeds-Shepp words tried per shot, shortest (cusps charged) first
    analytic_slack: float = 8.0  # ... only words at most this much longer than the shortest
    batch_size: int = 4  # open nodes expanded together in one vectorised call
    max_iterations: int = 1500  # node pops per query
    time_cap: float = 0.25  # seconds per query (wall clock; the iteration cap normally ends first)
    goal_tolerance_xy: float = 0.1  # goals are searched exactly; the tracked end state may miss them by this
    goal_tolerance_heading: float = math.radians(3.0)  # ... and by this heading error (parking plans)


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
    fallback_prediction: str = "constant_velocity"  # for observed agents without a prediction: | "static" | "none"
    fallback_horizon: float = 3.0  # seconds of the fallback constant-velocity prediction
    dynamic_as_static_fallback: bool = True  # replan around current agent footprints if all plans are blocked
    fallback_time_cap: float = 0.05  # seconds for that second round of searches
    fallback_max_iterations: int = 300  # node pops per search in that round
    evasive: bool = True  # if standing still is predicted to be hit, drive the plan that is hit latest
    decision_time_cap: float = 0.4  # seconds of searching per decision step (remaining candidates skipped)
    park_retry_steps: int = 5  # while exploring, parking is re-tried at least this often (and on any change)
    idle_replan_steps: int = 1  # after an idle decision (no safe plan) search again only this many steps later


@dataclass(frozen=True)
class PlannerSettings:
    """All settings of :class:`~avp_planner.core.decision.EgoPlanner`."""

    vehicle: VehicleSpec = field(default_factory=VehicleSpec)  # 4.6 x 1.85 m, R_min = 3.22 m (§II-B)
    collision: CollisionSettings = field(default_factory=CollisionSettings)
    search: SearchSettings = field(default_factory=SearchSettings)
    control: ControlSettings = field(default_factory=ControlSettings)
    cost: CostSettings = field(default_factory=CostSettings)
    decision: DecisionSettings = field(default_factory=DecisionSettings)

    @property
    def plan_radius(self) -> float:
        """R_plan = curvature_reserve * R_min: the turning radius of primitives and Reeds-Shepp shots."""
        return self.search.curvature_reserve * self.vehicle.min_turning_radius

    def validate(self) -> PlannerSettings:
        """Raise ValueError naming the first bad field; returns ``self``."""
        s, c, k, d = self.search, self.collision, self.control, self.decision
        checks = [
            ("collision.grid_resolution", c.grid_resolution > 0),
            ("collision.n_discs", c.n_discs >= 1),
            ("collision.footprint_margin", c.footprint_margin >= 0),
            ("collision.verify_margin", 0 <= c.verify_margin <= c.footprint_margin),
            ("collision.beyond_horizon", c.beyond_horizon in ("hold", "release")),
            ("search.xy_resolution", s.xy_resolution > 0),
            ("search.heading_bins", s.heading_bins >= 8),
            ("search.primitive_length", s.primitive_length > s.sample_step > 0),
            ("search.steering_fractions", len(s.steering_fractions) >= 1
             and all(abs(f) <= 1.0 for f in s.steering_fractions)),
            ("search.curvature_reserve", s.curvature_reserve >= 1.0),
            ("search.heuristic_weight", s.heuristic_weight >= 1.0),
            ("search.max_iterations", s.max_iterations >= 1),
            ("search.time_cap", s.time_cap > 0),
            ("control.dt", k.dt > 0),
            ("control.v_max", 0 < k.v_max <= self.vehicle.max_speed),
            ("control.a_max", k.a_max > 0),
            ("decision.belief_threshold", 0.0 <= d.belief_threshold <= 1.0),
            ("decision.candidate_threshold", 0.0 <= d.candidate_threshold < d.belief_threshold),
            ("decision.sensing_radius", d.sensing_radius > 0),
            ("decision.wait_step", d.wait_step > 0 and d.max_wait >= 0),
            ("decision.idle_replan_steps", d.idle_replan_steps >= 1),
            ("decision.fallback_prediction", d.fallback_prediction in ("constant_velocity", "static", "none")),
        ]
        for name, ok in checks:
            if not ok:
                raise ValueError(f"PlannerSettings.{name}: invalid value")
        return self


DEFAULT_SETTINGS = PlannerSettings()

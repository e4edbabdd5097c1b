"""Settings of the search core (ROS-free, frozen dataclasses): collision checking and Hybrid A* (paper §V-D).

:class:`SearchConfig` is what :class:`~avp_search.hybrid_astar.HybridAStar` and
:class:`~avp_search.collision.StaticWorld` read: the vehicle (§II-B), the collision margins and the search knobs.
The ego planner's :class:`~avp_planner.core.settings.PlannerSettings` extends it with tracking, cost and decision
settings; the Hybrid A* predictor passes the same struct. Where a knob is a symbol of the paper it is named in the
comment; the rest are the usual Hybrid A* settings (docs/planner.md compares them with Nawaz et al., Nav2 and
Autoware). Units: metres, seconds, radians.
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
    # mechanism b (beyond §V-D, which checks every predicted trajectory as an obstacle): > 0 = a plan meeting
    # a hypothesis only after this many seconds is blocked only when the hypotheses it meets there sum to more than
    # risk_bound in probability; 0 = every meeting blocks (the paper)
    commit_horizon: float = 0.0  # mechanism b: s of hard checks against every hypothesis, then beyond_commit (0: off)
    risk_bound: float = 0.5  # mechanism b, risk: hypotheses met past the window may sum to this probability
    # beyond the commit window: "risk" (the risk bound above) | "hold" (each hypothesis is an obstacle where it is at
    # the window's end, as §III-B's reactive agents stop for the ego; commit_horizon -> 0 is the `blind` bound)
    beyond_commit: str = "risk"  # mechanism b: "risk" (risk_bound) or "hold" (each hypothesis held at the window's end)
    # mechanism a in its interactive form (beyond §V-D, which checks each predicted trajectory as if the
    # agent went on whatever the ego does): > 0 = each hypothesis is rolled out against the ego's plan with §III-B's
    # rule, the agent braking while its next reactive_steps steps come within the margin + reactive_margin of the ego
    # (avp_search.reactive); 0 = the paper
    reactive_steps: int = 2  # agents stop for the ego, look-ahead L [steps] (avp_search.reactive); 0 = the paper
    reactive_margin: float = 0.0  # m beyond the margin at which an agent is assumed to brake for the ego
    # which agents reactive_steps applies to: "assumed" (every agent), "agent" (only agents seen to stop hard,
    # harder than reactive_decel, with the ego ahead of them within decision.yield_lookahead; remembered for the
    # episode), "lot" (every agent, once any has been seen to do so), "told" (the agents the caller names with
    # EgoPlanner.tell_reacting: the oracle bound's ground truth, avp_experiment.oracle)
    # shipped: "assumed"; before 0c50a9b "lot", now the planner profile `wary` (drivers may not stop)
    reactive_evidence: str = "assumed"  # whose reaction: assumed (all), agent (seen), lot (once seen), told (caller)
    # when an agent is assumed to brake for the ego: "margin" (its next reactive_steps poses come within the check's
    # margin + reactive_margin of the ego; the rule since 9c585c4) or "overlap" (they would overlap it +
    # reactive_margin: §III-B's "meets", the simulator's rule; an agent braking for the ego then meets it only if the
    # ego comes nearer)
    reactive_trigger: str = "margin"  # when a reacting agent is assumed to brake: margin or overlap (§III-B)
    reactive_decel: float = 3.0  # m/s^2 of braking (2x ParkSim's 1.5) that counts as stopping for the ego
    # how an agent the reaction applies to is predicted: "rollout" (each hypothesis rolled out against the ego's plan
    # with the braking rule above) or "hold" (held where it is now, as `blind` holds every agent: it will stop for the
    # ego, and the ego re-plans every step; an arm of docs/research/unfreezing.md)
    reactive_model: str = "rollout"  # a reacting agent rolled out with the braking rule, or held where it is
    # which predicted trajectories of an agent are obstacles: "all" (every hypothesis >= mu, §V-D-1 "the predicted
    # trajectories") or "most_likely" (only each agent's most probable one; an arm of docs/research/unfreezing.md)
    hypotheses: str = "all"  # all (§V-D-1) or most_likely (each agent's most probable hypothesis only)
    # the predicted trajectories of a car driving away from the ego (its velocity pointing away from the ego, faster
    # than 0.3 m/s): "hypotheses" (as given, §V-C) or "straight" (replaced by one: straight on at its last displacement,
    # the constant-velocity prediction of §VI-B-1; an arm of docs/research/unfreezing.md)
    receding: str = "hypotheses"  # a car driving away keeps its hypotheses (§V-C) or goes straight on


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
class SearchConfig:
    """The vehicle and the collision and search settings of one Hybrid A* query."""

    vehicle: VehicleSpec = field(default_factory=VehicleSpec)  # 4.6 x 1.85 m, R_min = 3.22 m (§II-B)
    collision: CollisionSettings = field(default_factory=CollisionSettings)
    search: SearchSettings = field(default_factory=SearchSettings)

    @property
    def plan_radius(self) -> float:
        """R_plan = curvature_reserve * R_min: the turning radius of primitives and Reeds-Shepp shots."""
        return self.search.curvature_reserve * self.vehicle.min_turning_radius

    def search_checks(self) -> list[tuple[str, bool]]:
        """(field, valid) for every checked field of the collision and search settings."""
        s, c = self.search, self.collision
        return [
            ("collision.grid_resolution", c.grid_resolution > 0),
            ("collision.n_discs", c.n_discs >= 1),
            ("collision.footprint_margin", c.footprint_margin >= 0),
            ("collision.verify_margin", 0 <= c.verify_margin <= c.footprint_margin),
            ("collision.beyond_horizon", c.beyond_horizon in ("hold", "release")),
            ("collision.beyond_commit", c.beyond_commit in ("risk", "hold")),
            ("collision.reactive_steps", c.reactive_steps >= 0),
            ("collision.reactive_margin", c.reactive_margin >= 0),
            ("collision.reactive_trigger", c.reactive_trigger in ("margin", "overlap")),
            ("collision.hypotheses", c.hypotheses in ("all", "most_likely")),
            ("collision.receding", c.receding in ("hypotheses", "straight")),
            ("collision.reactive_model", c.reactive_model in ("rollout", "hold")),
            ("collision.reactive_evidence", c.reactive_evidence in ("assumed", "agent", "lot", "told")),
            ("collision.reactive_decel", c.reactive_decel > 0),
            ("search.xy_resolution", s.xy_resolution > 0),
            ("search.heading_bins", s.heading_bins >= 8),
            ("search.primitive_length", s.primitive_length > s.sample_step > 0),
            ("search.steering_fractions", len(s.steering_fractions) >= 1
             and all(abs(f) <= 1.0 for f in s.steering_fractions)),
            ("search.curvature_reserve", s.curvature_reserve >= 1.0),
            ("search.heuristic_weight", s.heuristic_weight >= 1.0),
            ("search.max_iterations", s.max_iterations >= 1),
            ("search.time_cap", s.time_cap > 0),
        ]

    def validate(self):
        """Raise ValueError naming the first bad field; returns ``self``."""
        for name, ok in self.search_checks():
            if not ok:
                raise ValueError(f"{type(self).__name__}.{name}: invalid value")
        return self

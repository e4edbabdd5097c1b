"""Settings of the search core (ROS-free, frozen dataclasses): collision checking and Hybrid A* (paper §V-D).

:class:`SearchConfig` is what :class:`~avp_search.hybrid_astar.HybridAStar` and
:class:`~avp_collision.static.StaticWorld` read: the vehicle (§II-B), the collision margins and the search knobs.
The ego planner's :class:`~avp_motion.settings.PlannerSettings` extends it with tracking, cost and decision
settings; the Hybrid A* predictor passes the same struct. Where a knob is a symbol of the paper it is named in the
comment; the rest are the usual Hybrid A* settings (docs/planner.md compares them with Nawaz et al., Nav2 and
Autoware). Units: metres, seconds, radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from avp_collision.settings import CollisionSettings
from avp_world.vehicle import VehicleSpec

__all__ = ["CollisionSettings", "SearchSettings", "SearchConfig"]


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
            ("collision.localisation_sigmas", 0 <= c.localisation_sigmas <= 10),
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

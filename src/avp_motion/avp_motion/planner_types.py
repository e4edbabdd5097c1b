"""Types and constants of the ego planner (§V-D): the decision it returns, its plans and candidates."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from avp_collision.static import DynamicObstacles, StaticWorld
from avp_motion.control import Trajectory
from avp_search.paths import Path
from avp_world.types import Observation

PARK, EXPLORE, IDLE = "park", "explore", "idle"
STILL_SPEED = 0.3  # m/s: an agent slower than this counts as standing still (detour instead of waiting)
EXPLORE_BACK_AFTER = 3.0  # s the road ahead must stay blocked by agents only before turning back (§V-D-2)
WORLD_CACHE_SIZE = 8  # static worlds kept (see EgoPlanner._static_world)
#: searches remembered by (static world, ego pose, goals, limits): the same search ends the same way, so an ego that
#: stands in an unchanged scene (waiting for a plan that predicted agents block, or with no plan at all) does not
#: search again every step. Every outcome but one ended by the wall-clock cap (not repeatable) is kept: a path found
#: is the one the search finds whenever it runs to its end (lock-step lifts the cap: the same episode either way)
SEARCH_CACHE = 512
CONTAINED_MARGIN = 0.3  # m: a static vehicle this far inside an occupied spot is left out of the raster


@dataclass
class Decision:
    """What the planner decided at one step.

    mode: 'park' | 'explore' | 'idle'; spot_id: the target spot (-1 unless parking); goal: (3,) goal pose
    (None when idle); poses: (K, 3) the planned states from now on (poses[0] = current pose); controls:
    (K - 1, 2) the remaining controls; command: (v, ω) for this step; timings: seconds
    (``spot_selection_time``: candidate selection, ordering, pricing and prediction checks;
    ``path_planning_time``: Hybrid A* searches and tracking; ``total``); n_candidates: |I_can,0|;
    reason: why this mode (or why a plan was dropped); cost: c of the plan; stats: details; trace: the step's
    mode (park, explore, wait_and_go, detour, evasive, idle, parked) and, when idle or waiting, its cause
    (:mod:`avp_motion.trace`); wanted: (N, 3) when idle, the poses of the plan the ego is blocked on (the one
    met latest, whose blocker the trace names) — what a fleet's beacon announces (:mod:`avp_planner.core.ego_yield`).
    """

    mode: str
    spot_id: int = -1
    goal: np.ndarray | None = None
    poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    controls: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    command: tuple[float, float] = (0.0, 0.0)
    timings: dict = field(default_factory=dict)
    n_candidates: int = 0
    reason: str = ""
    cost: float = math.nan
    replanned: bool = False
    stats: dict = field(default_factory=dict)
    trace: dict = field(default_factory=dict)  # mode and idle cause of this step (avp_motion.trace)
    wanted: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # idle: the plan it is blocked on


@dataclass
class _Plan:
    mode: str
    spot_id: int
    goal: np.ndarray
    traj: Trajectory
    cost: float
    margins: np.ndarray  # static clearance each state keeps (0 near the start, verify_margin after)
    index: int = 0  # next control to send
    path_length: float = 0.0
    note: str = ""
    wait_steps: int = 0  # a wait-and-go plan: the steps it stands (decision trace) ...
    wait_from: int = 0  # ... from this control on (0: at its start; > 0: at a stop on the way, mechanism c)
    kind: str = ""  # "detour" / "evasive": how it was found (the trace's mode); "" = its mode
    wait_cause: dict = field(default_factory=dict)  # who it waits for (avp_motion.trace.blocker_trace)
    steer: np.ndarray | None = None  # decision.pose_drift steer: the estimate this step's control steers back from


@dataclass
class _Candidate:
    """One evaluated plan (before tracking)."""

    mode: str
    spot_id: int
    goal: np.ndarray
    path: Path
    cost: float
    wait_steps: int
    front: bool = True
    first_hit: int = -1  # blocked plans: first time index at which a predicted agent meets it (no wait)
    wait_on_path: bool = False  # the wait is at path.stops[0], not at the start (mechanism c)


@dataclass
class _Step:
    """What one decision step of :meth:`~avp_planner.core.decision.EgoPlanner.decide` works on: the
    observation, beliefs b, ego pose, static world, predicted obstacles, candidate spots (in ``spot_priority``
    order if ``ordered``), the timings and statistics it reports, its search deadline ``t_end``, and what the
    phases hand on (the shared heuristic and searcher, plans blocked by predicted agents, why the last plan
    was dropped)."""

    obs: Observation
    b: np.ndarray
    ego: np.ndarray
    world: StaticWorld
    dyn: DynamicObstacles
    cands: np.ndarray
    ordered: bool
    timing: dict
    t_start: float
    t_end: float
    stats: dict = field(default_factory=dict)
    heur: object = None
    astar: object = None
    blocked: bool = False
    blocked_plans: list[_Candidate] = field(default_factory=list)
    why: str = ""

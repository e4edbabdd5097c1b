"""What the training traffic generator (:mod:`.traffic`) is made of: its parameters, one agent's plan, an
episode's traffic, the library of ParkSim maneuvers moved onto the lot's spots, and small helpers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from avp_scenario.maneuvers import ManeuverKey, SceneGeometry, generate_maneuver, maneuver_to_world
from avp_scenario.scenario import Scenario
from avp_traffic.lanes import LaneGraph
from avp_world.geometry import polygon_contains_points, rect_corners
from avp_world.lot import LotMap
from avp_world.vehicle import VehicleSpec

PARK, LEAVE, WANDER = "park", "leave", "wander"
AGENT_ID0 = 10000  # ids of the traffic agents (parked cars keep their spot's row)


@dataclass(frozen=True)
class TrafficParams:
    """Knobs of the traffic generator (module docstring); times in s, distances in m, speeds in m/s."""

    dt: float = 0.1
    t_hist: float = 4.0
    t_final: float = 60.0  # episode length after t = 0
    t_pre: float = 40.0  # traffic simulated before t = -t_hist
    occupancy: tuple[float, float] = (0.5, 0.95)
    arrival_gap: tuple[float, float] = (4.0, 12.0)  # mean gap between arrivals, drawn per episode
    departure_gap: tuple[float, float] = (10.0, 30.0)
    min_arrival_gap: float = 3.0
    cruise_speed: tuple[float, float] = (2.0, 4.0)  # ParkSim cruises at up to 5 m/s (reference sheet §3.1)
    approach_speed: float = 2.0
    p_explore: float = 0.15  # share of parkers who search (the rest drive to a spot chosen at the entrance)
    preference_length: tuple[float, float] = (15.0, 60.0)  # goal choice: weight exp(-route length / L), L per driver
    p_take: tuple[float, float] = (0.3, 0.85)
    patience: float = 60.0
    far_factor: float = 0.7
    give_up: tuple[float, float] = (150.0, 400.0)
    p_stop_before: float = 0.8  # ParkSim overshoots ('after') only near the ends of rows
    p_head_in: float = 0.5
    slow_distance: tuple[float, float] = (6.0, 12.0)  # a parker rolls the last metres to its maneuver start ...
    slow_speed: tuple[float, float] = (0.8, 1.5)  # ... at this speed (ParkSim: v_end = 1 m/s, sheet §3.1)
    pause: tuple[float, float] = (0.0, 1.5)
    queue_distance: float = 12.0
    exit_distance: float = 15.0
    moving_margin: float = 0.3
    still_margin: float = 0.02
    tries: int = 4
    delays: int = 3
    delay: float = 3.0
    passiveness: tuple[int, int] = (2, 6)
    parked_length: float = 4.6
    parked_width: float = 1.85
    ego_speed: tuple[float, float] = (1.5, 3.0)
    ego_clearance: float = 1.0


@dataclass
class AgentPlan:
    """One traffic car on the generation timeline (index 0 = t_0 = -t_pre - t_hist)."""

    kind: str
    spot_row: int  # target (park) or start (leave) spot row; -1 for wanderers
    maneuver: str
    states: np.ndarray  # (K + 1, 3)
    controls: np.ndarray  # (K, 2)
    moving: np.ndarray  # (K + 1,) bool: moved into or out of this state
    drive_end: int = -1  # parkers: timeline index where the maneuver starts (the car stopped on its lane)
    end_lane: int = -1  # parkers: lane and lane coordinate of that stop
    end_t: float = 0.0
    cruise_speed: float = 0.0  # parkers: v_c and the final roll's length (slow_distance draw)
    roll_distance: float = 0.0
    # goal-directed parkers: the options (row, lane, side) the driver chose among and their weights (empty for
    # explorers) — for analysis (training.oracle); drawing them consumed no extra random numbers
    goal_options: tuple = ()
    goal_weights: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass
class Traffic:
    """A generated episode: the World scenario, a label per dynamic agent and the ego's plan."""

    scenario: Scenario
    labels: dict[int, int]  # vehicle id -> spot id it parks in, -1 = none (leaving, wandering)
    kinds: dict[int, str]
    ego_controls: np.ndarray  # (T, 2) the ego's tour; the runner holds it while blocked
    ego_states: np.ndarray  # (T + 1, 3)
    n_parked: int = 0
    stats: dict = field(default_factory=dict)
    plans: dict[int, AgentPlan] = field(default_factory=dict)  # vehicle id -> its plan (analysis only)


class ManeuverLibrary:
    """The 8 maneuvers per scene geometry (cached) and their world versions per spot, checked to stay inside
    the lot boundary."""

    _canon: dict = {}

    def __init__(self, lot: LotMap, graph: LaneGraph, spot_road: np.ndarray, vehicle: VehicleSpec):
        self.lot, self.graph, self.vehicle = lot, graph, vehicle
        self.spot_road = spot_road
        self._world: dict[tuple[int, ManeuverKey], tuple | None] = {}

    def scene(self, row: int) -> SceneGeometry:
        road = self.lot.roads[int(self.spot_road[row])]
        return SceneGeometry(aisle_width=round(road.width, 6), spot_length=round(float(self.lot.spot_dims[row, 0]), 6),
                             spot_width=round(float(self.lot.spot_dims[row, 1]), 6))

    def canonical(self, key: ManeuverKey, scene: SceneGeometry, dt: float):
        k = (key, scene, self.vehicle, dt)
        if k not in self._canon:
            try:
                self._canon[k] = generate_maneuver(key, scene, self.vehicle, dt)
            except RuntimeError:
                self._canon[k] = None
        return self._canon[k]

    def world(self, row: int, key: ManeuverKey, dt: float):
        """(start pose, states, controls) of maneuver ``key`` into spot ``row`` in world coordinates, or None if
        it leaves the lot or does not exist."""
        if (row, key) not in self._world:
            out = None
            scene = self.scene(row)
            man = self.canonical(key, scene, dt)
            if man is not None:
                start, states = maneuver_to_world(man, self.lot.spot_poses[row], scene.aisle_width, key.side)
                fp = rect_corners(states, self.vehicle.length, self.vehicle.width)
                if polygon_contains_points(self.lot.boundary, fp.reshape(-1, 2)).all():
                    out = (start, states, np.asarray(man.controls))
            self._world[(row, key)] = out
        return self._world[(row, key)]


def slow_tail(pieces: list[tuple[float, float, float]], distance: float, speed: float
              ) -> list[tuple[float, float, float]]:
    """Cap the speed at ``speed`` over the last ``distance`` metres of a path (splitting a piece if needed):
    a driver who has picked a spot rolls up to the maneuver start slowly."""
    out: list[tuple[float, float, float]] = []
    left = distance
    for length, kappa, cap in reversed(pieces):
        if left <= 0.0:
            out.append((length, kappa, cap))
        elif length <= left:
            out.append((length, kappa, min(cap, speed)))
            left -= length
        else:
            out.append((left, kappa, min(cap, speed)))
            out.append((length - left, kappa, cap))
            left = 0.0
    return out[::-1]


def moving_flags(states: np.ndarray) -> np.ndarray:
    step = np.abs(np.diff(states, axis=0)).max(axis=1) > 1e-9
    m = np.zeros(len(states), dtype=bool)
    m[1:] |= step
    m[:-1] |= step
    return m

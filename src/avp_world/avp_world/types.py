"""Plain data passed between the simulator, perception and planner cores (no ROS types).

:class:`Observation` is exactly what the ego may know at one step (paper §III-A): the ego pipeline
is built on it alone; ground truth never appears here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class ObservedVehicle:
    """A vehicle touched by a ray: size, static/dynamic flag and its states over t_hist (oldest first)."""

    id: int
    length: float
    width: float
    is_static: bool
    history: np.ndarray  # (H, 3) poses (x, y, theta) at t - t_hist ... t; history[-1] is the current state

    @property
    def pose(self) -> np.ndarray:
        return self.history[-1]


@dataclass(frozen=True)
class ObservedPedestrian:
    """A pedestrian touched by a ray: radius and positions at t - dt and t."""

    id: int
    radius: float
    position: np.ndarray  # (2,)
    previous_position: np.ndarray  # (2,)


@dataclass(frozen=True)
class Beacon:
    """An announcement another automated car sent over the fleet's radio (V2V), not something observed: who sent
    it, where it stands, whether it stands waiting, and the path it wants to drive (the plan it drives, or while it
    waits the plan it is blocked on). Only an ego of a fleet hears one (docs/world.md, "Several egos")."""

    ego: int  # the sender's index; it has the right of way over the receiver (the fleet's channel delivers so)
    pose: np.ndarray  # (3,) the sender's pose when it sent it
    waiting: bool  # it stands idle or waiting
    path: np.ndarray  # (N, 3) poses of the path it wants to drive, from its pose on


@dataclass(frozen=True)
class Observation:
    """The ego's observation at step ``step`` (time t = step * dt), paper §III-A."""

    step: int
    dt: float
    ego_pose: np.ndarray  # (3,)
    ego_length: float
    ego_width: float
    ego_speed: float
    vacant_spot_ids: np.ndarray  # I_vac,t (int64)
    occupied_spot_ids: np.ndarray  # I_occ,t (int64)
    vehicles: tuple[ObservedVehicle, ...] = ()
    pedestrians: tuple[ObservedPedestrian, ...] = ()
    ray_angle_min: float = 0.0  # relative to the ego heading
    ray_angle_increment: float = 0.0
    ray_ranges: np.ndarray = field(default_factory=lambda: np.zeros(0))
    beacons: tuple[Beacon, ...] = ()  # what egos with the right of way announced at the step before (V2V)
    # (3, 3) covariance of ego_pose over (x, y, theta), as a localiser reports it; None: exact (the paper's sensor)
    ego_covariance: np.ndarray | None = None

    @property
    def t(self) -> float:
        return self.step * self.dt

    def ray_endpoints(self) -> np.ndarray:
        """(n_ray, 2) world coordinates where each ray stopped."""
        n = len(self.ray_ranges)
        ang = self.ego_pose[2] + self.ray_angle_min + self.ray_angle_increment * np.arange(n)
        r = np.asarray(self.ray_ranges, dtype=float)
        return self.ego_pose[:2] + np.stack([r * np.cos(ang), r * np.sin(ang)], axis=1)


@dataclass(frozen=True)
class PredictedTrajectory:
    """One predicted future of one agent, conditioned on one intention (paper §V-C).

    ``poses[j]`` is the predicted state at t + (j + 1) * dt, where t is the observation time.
    """

    agent_id: int
    poses: np.ndarray  # (T, 3) for vehicles; (T, 3) with theta = 0 for pedestrians
    dt: float
    probability: float = 1.0  # eta of the conditioning intention
    is_pedestrian: bool = False
    length: float = 0.0  # vehicles
    width: float = 0.0
    radius: float = 0.0  # pedestrians
    spot_id: int = -1  # the intended spot, -1 for exploration / unconditioned
    goal: np.ndarray | None = None  # (3,) the conditioning goal (spot or exploration point); None: unconditioned


def priority_from_probabilities(spot_ids: Sequence[int], probabilities: Sequence[float]) -> np.ndarray:
    """Spot ids in decreasing probability, ties smaller id first: the ``spot_priority`` of the "Implicit" method
    (§VI-B-3) from the ego's own intention eta_0,i. Perception (avp_predictors.implicit) orders its
    intention with it, the planner node the ``ego_intention`` message."""
    ids = np.asarray(spot_ids, dtype=np.int64).reshape(-1)
    p = np.asarray(probabilities, dtype=float).reshape(-1)
    if len(ids) != len(p):
        raise ValueError(f"{len(ids)} spot ids but {len(p)} probabilities")
    return ids[np.lexsort((ids, -p))]

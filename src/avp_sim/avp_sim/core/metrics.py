"""§VI-B episode events and metrics as pure functions of the ground truth (docs/metrics.md).

:class:`~avp_sim.core.world.World` calls :func:`step_event` after every step; :func:`metrics_from_log`
recomputes a whole episode's metrics from logged ground truth (e.g. a bag), with the same code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from avp_world.geometry import disc_rect_overlap, polygon_contains_points, rect_corners, rect_inside_rect, rects_overlap
from avp_world.lot import LotMap

RUNNING, SUCCESS, COLLISION, TIMEOUT = "running", "success", "collision", "timeout"


@dataclass
class EpisodeMetrics:
    """§VI-B metrics of one episode."""

    success: bool = False
    collision: bool = False
    collision_with: str = ""
    collision_at_fault: bool = False  # the ego moved in the step it collided (docs/metrics.md)
    spot_stolen: bool = False
    parked_spot_id: int = -1
    interrupted_steps: int = 0
    interrupted_agent_steps: int = 0
    parking_time: float = float("nan")
    steps: int = 0

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def step_event(lot: LotMap, ego_corners: np.ndarray, vehicle_corners: np.ndarray, vehicle_ids: np.ndarray,
               ped_pos: np.ndarray, ped_radii: np.ndarray, ped_ids: np.ndarray) -> tuple[str, str, int]:
    """(status, collision_with, parked_spot_id) of one instant: collision first, then V_0 ⊆ S_i (Problem 1)."""
    if len(vehicle_corners):
        hit = rects_overlap(vehicle_corners, ego_corners[None])
        if hit.any():
            return COLLISION, f"vehicle:{int(vehicle_ids[int(np.argmax(hit))])}", -1
    if len(ped_pos):
        ped_hit = disc_rect_overlap(ped_pos, ped_radii, ego_corners[None])
        if ped_hit.any():
            return COLLISION, f"pedestrian:{int(ped_ids[int(np.argmax(ped_hit))])}", -1
    if not polygon_contains_points(lot.boundary, ego_corners).all():
        return COLLISION, "boundary", -1
    inside = rect_inside_rect(ego_corners[None], lot.spot_corners)
    if inside.any():
        return SUCCESS, "", int(lot.spot_ids[int(np.argmax(inside))])
    return RUNNING, "", -1


def apply_event(m: EpisodeMetrics, status: str, collision_with: str, parked: int, step: int, dt: float,
                t_final: float, dynamic_targets: np.ndarray, ego_moved: bool = True) -> str:
    """Fold one instant's event into the metrics; returns the episode status (timeout at t_f). ``ego_moved``: the
    ego's pose changed in the step that led to this instant (a collision is the ego's fault only then)."""
    m.steps = step
    if status == SUCCESS:
        m.parked_spot_id = parked
        m.parking_time = step * dt
        m.spot_stolen = bool(np.any(dynamic_targets == parked))  # a dynamic vehicle was heading for it
    elif status == RUNNING and step * dt >= t_final - 1e-9:
        status = TIMEOUT
    m.success = status == SUCCESS
    m.collision = status == COLLISION
    m.collision_with = collision_with
    m.collision_at_fault = m.collision and bool(ego_moved)
    return status


def metrics_from_log(lot: LotMap, dt: float, t_final: float, ego_dims: tuple[float, float],
                     ego: np.ndarray, vehicles: np.ndarray, dims: np.ndarray, ids: np.ndarray,
                     dynamic: np.ndarray, targets: np.ndarray, braking: np.ndarray,
                     peds: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> tuple[str, EpisodeMetrics]:
    """Recompute an episode from ground truth: ego (T, 3), vehicles (T, N, 3), braking (T, N) (step k's
    braking flag is the decision taken while moving from k - 1 to k; row 0 is ignored), pedestrians
    (positions (T, P, 2), radii (P,), ids (P,)) if any."""
    ped_pos, ped_r, ped_ids = peds if peds is not None else (np.zeros((len(ego), 0, 2)), np.zeros(0),
                                                            np.zeros(0, np.int64))
    m = EpisodeMetrics()
    status = RUNNING
    dyn_targets = targets[dynamic]
    for k in range(len(ego)):
        if k > 0:
            n = int((braking[k] & dynamic).sum())
            m.interrupted_agent_steps += n
            m.interrupted_steps += int(n > 0)
        ev, who, parked = step_event(lot, rect_corners(ego[k], *ego_dims), rect_corners(vehicles[k], dims[:, 0],
                                     dims[:, 1]), ids, ped_pos[k], ped_r, ped_ids)
        moved = k > 0 and not np.array_equal(ego[k], ego[k - 1])
        status = apply_event(m, ev, who, parked, k, dt, t_final, dyn_targets, moved)
        if status != RUNNING:
            break
    return status, m


def nan_to_none(x: float) -> float | None:
    return None if isinstance(x, float) and math.isnan(x) else x

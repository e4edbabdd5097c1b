"""The canonical scene of ParkSim's maneuver library (ROS-free): which of the 8 maneuvers (:class:`ManeuverKey`),
the aisle and spots (:class:`SceneGeometry`), the start, spot and goal poses and the parked cars around the
target spot; and the :class:`Maneuver` record. :mod:`avp_scenario.maneuvers` builds the maneuvers on it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from avp_world.geometry import wrap_angle
from avp_world.vehicle import VehicleSpec

START_OFFSET = 4.0  # |x0| of the start pose (ParkSim: -4 "left" / +4 "right")


class ManeuverKey(NamedTuple):
    """Which of the 8 maneuvers: side 'near'|'far', stop 'before'|'after', entry 'head_in'|'tail_in'."""

    side: str
    stop: str
    entry: str


ALL_MANEUVERS: tuple[ManeuverKey, ...] = tuple(
    ManeuverKey(side, stop, entry)
    for side in ("near", "far")
    for stop in ("before", "after")
    for entry in ("head_in", "tail_in")
)


@dataclass(frozen=True)
class SceneGeometry:
    """The canonical scene (paper lot defaults: 7 m aisle, 5.5 x 2.75 m spots).

    clearance: minimum distance (m) a maneuver keeps to the parked cars and the geofence.
    """

    aisle_width: float = 7.0
    spot_length: float = 5.5
    spot_width: float = 2.75
    clearance: float = 0.15

    @property
    def lane_y(self) -> float:
        """Centre line of the right-hand lane for a car driving east."""
        return -self.aisle_width / 4.0

    @property
    def spot_y(self) -> float:
        """|y| of the spot centres."""
        return self.aisle_width / 2.0 + self.spot_length / 2.0

    @property
    def geofence(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) = x in [-10, 10], y in [-(aisle/2 + spot_length), +(...)]."""
        h = self.aisle_width / 2.0 + self.spot_length
        return (-10.0, -h, 10.0, h)


@dataclass(frozen=True, eq=False)
class Maneuver:
    """A maneuver in the canonical scene frame.

    start: (3,) pose with v = 0; controls: (T, 2) = (v, omega) per dt; states: (T + 1, 3) =
    ``rollout_vehicle(start, controls, dt)`` exactly (eq. (1)); scene: the geometry it was made for.
    Arrays are read-only (results are cached); equality is identity.
    """

    key: ManeuverKey
    start: np.ndarray
    controls: np.ndarray
    states: np.ndarray
    dt: float = 0.1
    scene: SceneGeometry = SceneGeometry()

    @property
    def duration(self) -> float:
        return self.controls.shape[0] * self.dt

    @property
    def n_cusps(self) -> int:
        """Number of driving-direction reversals of the controls."""
        v = self.controls[:, 0]
        s = np.sign(v[np.abs(v) > 1e-9])
        return int(np.count_nonzero(s[1:] != s[:-1]))


def check_key(key: ManeuverKey) -> ManeuverKey:
    key = ManeuverKey(*key)
    if key.side not in ("near", "far") or key.stop not in ("before", "after"):
        raise ValueError(f"bad maneuver key {key}")
    if key.entry not in ("head_in", "tail_in"):
        raise ValueError(f"bad maneuver key {key}")
    return key


def target_spot_pose(side: str, scene: SceneGeometry = SceneGeometry()) -> np.ndarray:
    """Centre and heading (pointing away from the aisle) of the target spot in the canonical frame."""
    if side == "near":
        return np.array([0.0, -scene.spot_y, -0.5 * math.pi])
    if side == "far":
        return np.array([0.0, scene.spot_y, 0.5 * math.pi])
    raise ValueError(f"side must be 'near' or 'far', got {side!r}")


def start_pose(key: ManeuverKey, scene: SceneGeometry = SceneGeometry()) -> np.ndarray:
    """(x0, -aisle/4, 0): x0 = -4 m (stop before the spot) or +4 m (after it)."""
    key = check_key(key)
    x0 = -START_OFFSET if key.stop == "before" else START_OFFSET
    return np.array([x0, scene.lane_y, 0.0])


def goal_pose(key: ManeuverKey, scene: SceneGeometry = SceneGeometry()) -> np.ndarray:
    """Spot centre with heading = spot heading (head-in) or spot heading + pi (tail-in), wrapped."""
    key = check_key(key)
    g = target_spot_pose(key.side, scene)
    if key.entry == "tail_in":
        g[2] = float(wrap_angle(g[2] + math.pi))
    return g


def parked_car_poses(
    side: str, scene: SceneGeometry = SceneGeometry(), vehicle: VehicleSpec = VehicleSpec()
) -> np.ndarray:
    """(P, 3) poses of the parked cars: every spot of both rows (x = k * spot_width) except the target,
    each holding a car of ``vehicle``'s size centred in it along the spot axis, as far as it reaches into
    the geofence."""
    xmin, _, xmax, _ = scene.geofence
    kmax = int(math.ceil((max(-xmin, xmax) + vehicle.width) / scene.spot_width))
    out = []
    for row_side, y, th in (("near", -scene.spot_y, -0.5 * math.pi), ("far", scene.spot_y, 0.5 * math.pi)):
        for k in range(-kmax, kmax + 1):
            x = k * scene.spot_width
            if k == 0 and row_side == side:
                continue
            if x + vehicle.width / 2 <= xmin or x - vehicle.width / 2 >= xmax:
                continue
            out.append((x, y, th))
    return np.array(out, dtype=float)

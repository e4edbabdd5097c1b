"""A placeholder ego driver (ROS-free): follows the nearest road's centre line and stops for obstacles.

It exists only so that the live graph can run end to end before the Hybrid A* planner of §V-D
replaces it. It never parks on purpose. Inputs: the lot map and the ego's
:class:`~avp_world.types.Observation` only (no ground truth).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from avp_world.geometry import rect_corners
from avp_world.lot import LotMap
from avp_world.types import Observation


@dataclass(frozen=True)
class ScriptedDriverConfig:
    speed: float = 1.5  # cruise speed [m/s]
    lookahead: float = 4.0  # pure-pursuit look-ahead distance [m]
    stop_distance: float = 6.0  # stop if an observed vehicle is this close ahead in the corridor [m]
    corridor_half_width: float = 1.6  # half width of the corridor checked ahead [m]
    road_end_margin: float = 4.0  # stop this far before the end of the road being followed [m]


class ScriptedDriver:
    def __init__(self, lot: LotMap, config: ScriptedDriverConfig = ScriptedDriverConfig()):
        self.lot = lot
        self.config = config

    def _road_frame(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """Nearest road centre line (oriented along the ego heading): (point on it, unit direction, length left)."""
        best = None
        for road in self.lot.roads:
            a, b = np.array(road.start), np.array(road.end)
            d = b - a
            length = float(np.linalg.norm(d))
            u = d / length
            if np.dot(u, [math.cos(pose[2]), math.sin(pose[2])]) < 0:  # drive it the ego's way
                a, b, u = b, a, -u
            s = float(np.clip(np.dot(pose[:2] - a, u), 0.0, length))
            foot = a + s * u
            dist = float(np.linalg.norm(pose[:2] - foot))
            align = float(np.dot(u, [math.cos(pose[2]), math.sin(pose[2])]))
            score = dist - 2.0 * align
            if best is None or score < best[0]:
                best = (score, foot, u, length - s)
        assert best is not None
        return best[1], best[2], best[3]

    def command(self, obs: Observation) -> tuple[float, float]:
        """(v, omega) for the current observation."""
        cfg = self.config
        pose = np.asarray(obs.ego_pose, dtype=float)
        foot, u, left = self._road_frame(pose)
        if left < cfg.road_end_margin:
            return 0.0, 0.0
        heading = np.array([math.cos(pose[2]), math.sin(pose[2])])
        normal = np.array([-heading[1], heading[0]])
        for veh in obs.vehicles:
            corners = rect_corners(veh.pose, veh.length, veh.width) - pose[:2]
            ahead = corners @ heading
            lateral = corners @ normal
            near = (ahead > 0) & (ahead < cfg.stop_distance + obs.ego_length / 2)
            if np.any(near & (np.abs(lateral) < cfg.corridor_half_width)):
                return 0.0, 0.0
        target = foot + cfg.lookahead * u
        rel = target - pose[:2]
        alpha = math.atan2(float(rel @ normal), float(rel @ heading))
        curvature = 2.0 * math.sin(alpha) / cfg.lookahead
        return cfg.speed, cfg.speed * curvature

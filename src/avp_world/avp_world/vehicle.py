"""Vehicle and pedestrian parameters (paper §II-B/C; sizes from ParkSim, see docs/world.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class VehicleSpec:
    """A rectangular Reeds-Shepp car (eq. 1).

    length/width: the rectangle V_k (ParkSim body 4.6 x 1.85 m).
    wheelbase/max_steer: give the minimum turning radius R_min = wheelbase / tan(max_steer)
    (2.7 m, 40 deg -> 3.22 m), i.e. |omega| <= |v| / R_min.
    """

    length: float = 4.6  # l_V0 [m], rectangle along the heading (§II-B; ParkSim body)
    width: float = 1.85  # w_V0 [m] (§II-B)
    wheelbase: float = 2.7  # [m]; with max_steer gives R_min = wheelbase / tan(max_steer) = 3.22 m
    max_steer: float = math.radians(40.0)  # [rad] (ParkSim)
    max_speed: float = 5.0  # |v| limit [m/s] (ParkSim)

    @property
    def min_turning_radius(self) -> float:
        return self.wheelbase / math.tan(self.max_steer)

    @property
    def max_curvature(self) -> float:
        return 1.0 / self.min_turning_radius


DEFAULT_VEHICLE = VehicleSpec()

"""What a real car's perception gives at one step: a detector's objects of this step only, with no identity and no
history, and a localisation estimate of the ego (docs/perception.md, "Sensing"). The simulator's sensing model
(avp_sensing.noisy) makes them; the tracker (avp_tracking) turns them into tracks. Plain data, ROS-free.

The ROS form of :class:`SensedFrame`'s objects is Autoware's ``autoware_perception_msgs/DetectedObjects``
(avp_tracking.conversions): :data:`LABEL_CAR` and :data:`LABEL_PEDESTRIAN` are its labels, and
:data:`ORIENTATION_AVAILABLE` / :data:`ORIENTATION_SIGN_UNKNOWN` its orientation availability.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

LABEL_UNKNOWN = 0
LABEL_CAR = 1
LABEL_PEDESTRIAN = 7
ORIENTATION_UNAVAILABLE = 0
ORIENTATION_SIGN_UNKNOWN = 1
ORIENTATION_AVAILABLE = 2


@dataclass(frozen=True)
class VehicleDetection:
    """One detected vehicle box in the map frame, as the ego places it with its localisation estimate."""

    pose: np.ndarray  # (3,) x, y, theta
    length: float
    width: float
    covariance: np.ndarray  # (3, 3) over x, y, theta
    existence: float = 1.0  # the detector's confidence, 0..1
    label: int = LABEL_CAR
    orientation: int = ORIENTATION_AVAILABLE
    speed: float = float("nan")  # a speed estimate along the heading [m/s], nan where the detector gives none
    speed_variance: float = float("nan")


@dataclass(frozen=True)
class PedestrianDetection:
    """One detected pedestrian (a disc) in the map frame."""

    position: np.ndarray  # (2,)
    radius: float
    covariance: np.ndarray  # (2, 2)
    existence: float = 1.0


@dataclass(frozen=True)
class SensedFrame:
    """Everything a noisy sensor gives at step ``step``: the ego's pose as its localisation estimates it, the spots
    it reads as vacant or occupied (some misread), its rays, and the detections (no ids, no histories)."""

    step: int
    dt: float
    ego_pose: np.ndarray  # (3,) the localisation estimate
    ego_covariance: np.ndarray  # (3, 3)
    ego_length: float
    ego_width: float
    ego_speed: float
    vacant_spot_ids: np.ndarray
    occupied_spot_ids: np.ndarray
    vehicles: tuple[VehicleDetection, ...] = ()
    pedestrians: tuple[PedestrianDetection, ...] = ()
    ray_angle_min: float = 0.0
    ray_angle_increment: float = 0.0
    ray_ranges: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.float32))

    @property
    def t(self) -> float:
        return self.step * self.dt

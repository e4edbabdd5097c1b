"""Two guards of the tracker against cars the sensor misses near the ego (docs/perception.md, "Tracking"), both
off by default and each a named parameter.

Under noisy sensing a car close to the ego and partly hidden is missed step after step (its detection probability
falls with the share of its outline the rays see). Its track then coasts on at its last speed, or is dropped after
``max_coast``, and the planner is left a free path where a car is — the busy lot's at-fault collisions
(docs/results/sensing/README.md). The paper gives the ego exact histories (§III-A) and has neither.

* **Near hold** (``near_hold_radius``, ``near_hold_max``): a confirmed vehicle track unseen longer than ``max_coast``
  whose centre lies within ``near_hold_radius`` of the ego's estimate is not dropped but kept standing (speed and
  yaw rate 0) for at most ``near_hold_max`` more seconds. It goes when it is seen again (and is tracked as before),
  when the ego's estimate leaves the radius, or when a ray of the ego's scan passes through its centre (free space
  where the track stands: the car has gone).
* **Box grown with the covariance** (``box_sigmas``): a moving vehicle track's box as given to the ego is longer and
  wider by ``box_sigmas`` standard deviations of its position estimate at each side (the largest eigenvalue of the
  position covariance), so a coasted track, whose covariance grows with each unseen step, covers where the car may
  be. A stationary (held) track's box is not grown: its covariance is a parked car's.
"""

from __future__ import annotations

import math

import numpy as np

from avp_tracking.core.tracks import Track
from avp_world.detections import SensedFrame

#: a ray must pass this far beyond a held track's centre to clear it [m]
CLEAR_BEYOND = 0.5


def keep_near(t: Track, frame: SensedFrame, max_misses: int, radius: float, hold_max: float) -> bool:
    """Whether confirmed vehicle track ``t``, unseen for ``t.misses`` steps (more than ``max_misses``), is kept
    standing near the ego (module docstring); sets it standing when it is."""
    if radius <= 0 or t.pedestrian or not t.confirmed or frame.dt <= 0:
        return False
    if (t.misses - max_misses) * frame.dt > hold_max:
        return False
    ego = np.asarray(frame.ego_pose, float)
    d = math.hypot(float(t.x[0] - ego[0]), float(t.x[1] - ego[1]))
    if d > radius or ray_passes(frame, t.x[:2], d):
        return False
    t.x[3] = t.x[4] = 0.0
    return True


def ray_passes(frame: SensedFrame, xy: np.ndarray, d: float) -> bool:
    """Whether the ray of ``frame``'s scan nearest the bearing of ``xy`` (at distance ``d`` from the ego) reaches
    beyond it by :data:`CLEAR_BEYOND`: free space where a track stands."""
    ranges = np.asarray(frame.ray_ranges, float)
    if not len(ranges) or frame.ray_angle_increment <= 0:
        return False
    ego = np.asarray(frame.ego_pose, float)
    bearing = math.atan2(float(xy[1] - ego[1]), float(xy[0] - ego[0])) - float(ego[2]) - frame.ray_angle_min
    i = int(round((bearing % (2.0 * math.pi)) / frame.ray_angle_increment)) % len(ranges)
    return bool(ranges[i] > d + CLEAR_BEYOND)


def grown_dims(t: Track, sigmas: float) -> tuple[float, float]:
    """(length, width) of vehicle track ``t`` given to the ego: its box, grown by ``sigmas`` standard deviations of
    its position at each side unless it is stationary or ``sigmas`` is 0."""
    length, width = t.dims
    if sigmas <= 0 or t.pedestrian or t.stationary:
        return length, width
    sd = math.sqrt(max(float(np.linalg.eigvalsh(t.P[:2, :2])[-1]), 0.0))
    return length + 2.0 * sigmas * sd, width + 2.0 * sigmas * sd

"""A driven plan kept where it is and steered back to under a drifting pose estimate (``decision.pose_drift`` steer;
beyond the paper).

§V-D re-checks the plan being executed at every step and drops it when the ego is 5 cm or 0.02 rad from the plan's
state; the planner then sends the plan's own controls (open loop). Under a localiser's estimate the ego follows its
controls exactly but the estimate drifts a few centimetres within seconds, so the paper's re-check drops the plan
every few steps (docs/research/sensing_noise.md). ``decision.pose_drift`` reanchor moves the plan onto the estimate
(:mod:`avp_motion.reanchor`), which turns its end about the ego by the heading error. Here, instead, the plan stays
in the lot's frame, where its spot is, and within ``decision.replan_pose_sigmas`` standard deviations of the
localiser's covariance the planner steers the estimate back onto it, as the plan's own tracker does
(:func:`avp_motion.control.track`): the heading after the step is the plan's minus d atan(e_lat / L), e_lat being
the lateral error of the position the step reaches and d = ±1 the driving direction; the speed is the plan's.
"""

from __future__ import annotations

import math

import numpy as np

from avp_motion.reanchor import deviation


def steer_control(states: np.ndarray, controls: np.ndarray, k: int, pose: np.ndarray, dt: float,
                  correction_length: float, max_curvature: float) -> tuple[float, float]:
    """The control (v, ω) of step ``k`` of a plan (``states`` (n + 1, 3) from ``controls`` (n, 2) by eq. 1) for
    an ego estimated at ``pose``: the plan's speed, ω turning the estimate's heading back onto the plan's line,
    |ω| <= |v| max_curvature."""
    v = float(controls[k, 0])
    if abs(v) < 1e-9:
        return v, 0.0
    x, y, th = (float(a) for a in pose[:3])
    nx_, ny_ = x + v * dt * math.cos(th), y + v * dt * math.sin(th)
    rx, ry, rth = (float(a) for a in states[k + 1])
    e_lat = -math.sin(rth) * (nx_ - rx) + math.cos(rth) * (ny_ - ry)  # left of the plan's line > 0
    target = rth - math.copysign(1.0, v) * math.atan(e_lat / correction_length)
    err = (target - th + math.pi) % (2.0 * math.pi) - math.pi
    lim = abs(v) * max_curvature * (1.0 - 1e-12)
    return v, min(max(err / dt, -lim), lim)


def heading_allowance(off: float, correction_length: float) -> float:
    """The heading the steering itself may add at a position error ``off`` (rad)."""
    return math.atan(off / correction_length)


def follows(states: np.ndarray, k: int, pose: np.ndarray, tolerance: tuple[float, float],
            correction_length: float) -> bool:
    """Whether the estimate ``pose`` is within ``tolerance`` (position, heading) of the plan's state ``k``, the
    heading allowed the steering's own turn on top."""
    off, dth = deviation(np.asarray(states[k], dtype=float), np.asarray(pose, dtype=float))
    return off <= tolerance[0] and dth <= tolerance[1] + heading_allowance(tolerance[0], correction_length)

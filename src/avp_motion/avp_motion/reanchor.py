"""A driven plan re-anchored at the ego's pose estimate (``decision.replan_pose_sigmas``; beyond the paper).

§V-D re-checks the plan being executed at every step, and the planner drops it when the ego is more than
``decision.replan_pose_tolerance`` (5 cm) or 0.02 rad from the plan's state. With the paper's exact sensing that
happens only when the ego does not follow its controls. With a localiser's estimate the ego follows them exactly,
but the estimate drifts (docs/perception.md, "Sensing"): a few centimetres within seconds, so the plan is dropped
and searched again every few steps, and a new search from a pose a few centimetres aside often ends in another
manoeuvre (a reversal near the spot, another spot). Everything the ego senses moves with the same estimate, so in
the frame of the current estimate the ego's own future under the same controls is the rest of the plan moved
rigidly onto the current pose. Within k standard deviations of the localiser's covariance (k =
``decision.replan_pose_sigmas``) the planner moves it so, and goes on checking it against the obstacles as the
paper does; beyond them, or with exact sensing (no covariance), or with k = 0 (the paper), the plan is dropped as
before.

The drive moved so ends where the plan was first aimed, and a heading error at that moment turns the whole plan about
the ego: at 15 m from the spot, 0.025 rad puts its end 0.37 m aside. The paper's re-check, searching again near the
spot, aims from a short lever arm. A parking plan with less than ``decision.replan_pose_near`` metres left is therefore
not moved: there the paper's re-check applies (0 = moved to the end).
"""

from __future__ import annotations

import math

import numpy as np

from avp_search.paths import wrap

HEADING_TOLERANCE = 0.02  # rad: the plan's own heading tolerance (with decision.replan_pose_tolerance in position)


def follow_tolerance(covariance: np.ndarray | None, sigmas: float, position_tolerance: float
                     ) -> tuple[float, float]:
    """(position, heading) deviation from the plan's state within which a driven plan is re-anchored: k times the
    larger position standard deviation and the heading's, never below the plan's own tolerances."""
    if covariance is None or sigmas <= 0:
        return position_tolerance, HEADING_TOLERANCE
    cov = np.asarray(covariance, dtype=float).reshape(3, 3)
    sigma_xy = math.sqrt(max(0.0, float(np.linalg.eigvalsh(cov[:2, :2]).max())))
    sigma_th = math.sqrt(max(0.0, float(cov[2, 2])))
    return max(position_tolerance, sigmas * sigma_xy), max(HEADING_TOLERANCE, sigmas * sigma_th)


def reanchored(states: np.ndarray, k: int, pose: np.ndarray) -> np.ndarray:
    """``states`` with ``states[k:]`` moved by the rigid motion that takes ``states[k]`` onto ``pose`` (x, y, θ);
    the states before k are kept."""
    out = np.array(states, dtype=float, copy=True)
    ref, pose = out[k].copy(), np.asarray(pose, dtype=float)[:3]
    dth = math.atan2(math.sin(pose[2] - ref[2]), math.cos(pose[2] - ref[2]))
    c, s = math.cos(dth), math.sin(dth)
    rel = out[k:, :2] - ref[:2]
    out[k:, 0] = pose[0] + c * rel[:, 0] - s * rel[:, 1]
    out[k:, 1] = pose[1] + s * rel[:, 0] + c * rel[:, 1]
    out[k:, 2] = np.arctan2(np.sin(out[k:, 2] + dth), np.cos(out[k:, 2] + dth))
    return out


def remaining_length(controls: np.ndarray, dt: float) -> float:
    """Metres of path the ``controls`` (v, ω) still drive."""
    return float(np.abs(np.asarray(controls, dtype=float)[:, 0]).sum() * dt)


def deviation(state: np.ndarray, pose: np.ndarray) -> tuple[float, float]:
    """(position, |heading|) distance of ``pose`` from the plan's ``state``, as §V-D's re-check reads it."""
    return math.hypot(*(state[:2] - pose[:2])), abs(float(wrap(state[2] - pose[2])))

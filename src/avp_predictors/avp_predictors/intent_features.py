"""Scalar features of the intent model (ROS-free): ParkPredict+'s five (cos to the target, distance to it, speed,
distance to the entrance, time in the lot) and our motion features from the observed history (§III-A), which
:class:`~avp_predictors.intent_model.SmallRegularizedCNN` reads beside the BEV image (docs/intent_model.md).
"""

from __future__ import annotations

import math

import numpy as np

#: how the intent model runs on a step's images (intent_model.IntentPredictor); here, apart from torch, for the
#: parameter specs of nodes that never load the model
INTENT_MODES = ("incremental", "fused", "reference")

PARKPREDICT_FEATURES = ("cos_to_target", "distance_to_target", "speed", "distance_to_entrance", "time_in_lot_min")
SPEED_WINDOWS = 4  # past 1 s windows of the motion features (4 s: the history the observation model gives)
MOTION_FEATURES = ("sin_to_target", *(f"mean_speed_{j}_{j + 1}s" for j in range(SPEED_WINDOWS)),
                   "heading_change_2s", "slow_roll_distance")
FEATURE_NAMES = PARKPREDICT_FEATURES + MOTION_FEATURES
N_FEATURES = len(FEATURE_NAMES)  # 12
MOTION_COLUMN = FEATURE_NAMES.index("mean_speed_0_1s")  # 6: the first column computed from the history
ROLL_COLUMN = FEATURE_NAMES.index("slow_roll_distance")  # 11
ROLL_SPEED = 1.6  # m/s: "slow" for slow_roll_distance (parkers roll their last 6-12 m at 0.8-1.5 m/s, cruise 2-4)


def motion_features(history: np.ndarray | None, dt: float, speed: float) -> np.ndarray:
    """The vehicle's motion over its observed history (our extension of §V-A, module docstring):
    [mean speed over [t-1, t], [t-2, t-1], [t-3, t-2], [t-4, t-3] s (path length of the history poses in the
    window / 1 s), heading change over the last 2 s (wrapped, rad)]. Windows the history does not reach repeat
    the oldest one measured; with fewer than two poses every speed is ``speed`` and the heading change 0."""
    out = np.full(SPEED_WINDOWS + 1, float(speed))
    out[-1] = 0.0
    if history is None or dt <= 0:
        return out
    h = np.asarray(history, dtype=float).reshape(-1, 3)
    if len(h) < 2:
        return out
    step = np.hypot(np.diff(h[:, 0]), np.diff(h[:, 1]))[::-1]  # newest first
    n = max(1, int(round(1.0 / dt)))
    for j in range(SPEED_WINDOWS):
        seg = step[j * n:(j + 1) * n]
        if len(seg) == 0:
            out[j] = out[j - 1]
        else:
            out[j] = float(seg.sum()) / (len(seg) * dt)
    back = min(len(h) - 1, 2 * n)
    out[-1] = math.remainder(h[-1, 2] - h[-1 - back, 2], math.tau)
    return out


def intent_features(pose: np.ndarray, speed: float, targets: np.ndarray, entrance: np.ndarray,
                    time_in_lot_min: float, history: np.ndarray | None = None, dt: float = 0.1,
                    roll_distance: float = 0.0) -> np.ndarray:
    """(K + 1, 12) float32 features: row 0 the "none" option, rows 1..K the candidate spot centres ``targets``.
    Columns: ParkPredict+'s five [cos_k,i, d_k,i, v_hat_k, d_ent, t_lot] (the "none" row [0, 0, v_hat, d_ent,
    t_lot]), then sin_k,i (the spot's side: + left; 0 for "none"), :func:`motion_features` of ``history``
    (past poses at ``dt``, oldest first, ending with the current one) and ``roll_distance``
    (:meth:`IntentPredictor.roll_distance`)."""
    tg = np.asarray(targets, dtype=float).reshape(-1, 2)
    p = np.asarray(pose, dtype=float)
    d = tg - p[:2]
    dist = np.hypot(d[:, 0], d[:, 1])
    c, s = math.cos(p[2]), math.sin(p[2])
    cos = (d @ np.array([c, s])) / np.maximum(dist, 1e-9)
    sin = (d @ np.array([-s, c])) / np.maximum(dist, 1e-9)
    cos[dist < 1e-9] = 1.0  # on top of the spot: aligned by convention
    sin[dist < 1e-9] = 0.0
    d_ent = float(np.hypot(*(p[:2] - np.asarray(entrance, dtype=float)[:2])))
    out = np.empty((len(tg) + 1, N_FEATURES), dtype=np.float32)
    out[0, :6] = (0.0, 0.0, speed, d_ent, time_in_lot_min, 0.0)
    out[1:, 0] = cos
    out[1:, 1] = dist
    out[1:, 2] = speed
    out[1:, 3] = d_ent
    out[1:, 4] = time_in_lot_min
    out[1:, 5] = sin
    out[:, MOTION_COLUMN:ROLL_COLUMN] = motion_features(history, dt, speed)[None]
    out[:, ROLL_COLUMN] = roll_distance
    return out

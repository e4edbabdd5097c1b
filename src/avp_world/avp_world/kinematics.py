"""Discrete-time dynamics of the paper: the Reeds-Shepp car, eq. (1), and the holonomic pedestrian, eq. (2)."""

from __future__ import annotations

import math

import numpy as np

from avp_world.geometry import wrap_angle


def brake_speed(rem: float, dt: float, dv: float) -> float:
    """Largest speed v for this step such that after moving v dt the rest, ``rem`` - v dt, can still be covered
    while slowing by ``dv`` per step to a stop in whole steps of eq. (1) (the discrete trapezoid every speed
    profile of the stack uses: the planner's tracker, the agents' maneuvers, the training traffic).

    With v in [n dv, (n + 1) dv) the distance is dt ((n + 1) v - dv n (n + 1) / 2), so v is that of the smallest
    n for which rem / (dt (n + 1)) + dv n / 2 < (n + 1) dv; the left side falls and the right side grows with n,
    so the search starts near the continuous answer v = sqrt(2 rem dv / dt) and walks to that n."""
    if rem <= 0:
        return 0.0
    if dv <= 0:
        return math.inf

    def ok(n: int) -> bool:
        return rem / (dt * (n + 1)) + dv * n / 2.0 < (n + 1) * dv

    n = max(0, int(math.sqrt(2.0 * rem / (dv * dt))) - 2)
    while n > 0 and ok(n - 1):
        n -= 1
    while not ok(n):
        n += 1
    return max(rem / (dt * (n + 1)) + dv * n / 2.0, n * dv)


def step_vehicle(state: np.ndarray, control: np.ndarray, dt: float) -> np.ndarray:
    """Eq. (1): s_{t+dt} = s_t + [v cos(theta), v sin(theta), omega] dt, heading wrapped to [-pi, pi).

    Args:
        state: (..., 3) poses (x, y, theta).
        control: (..., 2) controls (v, omega).
    """
    s = np.asarray(state, dtype=float)
    u = np.asarray(control, dtype=float)
    v, om = u[..., 0], u[..., 1]
    th = s[..., 2]
    out = np.empty(np.broadcast_shapes(s.shape, u.shape[:-1] + (3,)))
    out[..., 0] = s[..., 0] + v * np.cos(th) * dt
    out[..., 1] = s[..., 1] + v * np.sin(th) * dt
    out[..., 2] = wrap_angle(th + om * dt)
    return out


def rollout_vehicle(state0: np.ndarray, controls: np.ndarray, dt: float) -> np.ndarray:
    """Apply eq. (1) along a control sequence.

    Args:
        state0: (..., 3) initial pose; controls: (T, ..., 2).

    Returns:
        (T + 1, ..., 3) poses, the first being ``state0``.
    """
    controls = np.asarray(controls, dtype=float)
    out = np.empty((controls.shape[0] + 1,) + np.broadcast_shapes(np.shape(state0), controls.shape[1:-1] + (3,)))
    out[0] = state0
    for k in range(controls.shape[0]):
        out[k + 1] = step_vehicle(out[k], controls[k], dt)
    return out


def step_pedestrian(position: np.ndarray, control: np.ndarray, dt: float) -> np.ndarray:
    """Eq. (2): p_{t+dt} = p_t + [v cos(theta), v sin(theta)] dt with control (v, theta)."""
    p = np.asarray(position, dtype=float)
    u = np.asarray(control, dtype=float)
    return p + np.stack([u[..., 0] * np.cos(u[..., 1]), u[..., 0] * np.sin(u[..., 1])], axis=-1) * dt

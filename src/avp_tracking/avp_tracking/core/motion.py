"""Motion models of the tracker's extended Kalman filters (docs/perception.md, "Tracking").

Vehicles: constant turn rate and velocity (CTRV) with a **signed** speed, state (x, y, theta, v, omega): a car that
reverses has v < 0, and one that turns hard at walking pace (ParkSim's parking maneuvers) keeps a yaw rate omega that
does not depend on v, as Autoware's bicycle model's would not at v = 0. Pedestrians: constant velocity, state
(x, y, vx, vy). The process noise is white acceleration (longitudinal, and yaw acceleration for omega) plus a small
lateral term for what the model misses (slip, a box's centre moving on a turning car).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def wrap(a: float) -> float:
    """``a`` wrapped to [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True)
class MotionNoise:
    """Process noise of the models (tracking.*)."""

    accel_sigma: float = 2.0  # m/s^2, longitudinal acceleration of a vehicle
    yaw_accel_sigma: float = 1.5  # rad/s^2
    lateral_sigma: float = 0.3  # m/s, lateral velocity the CTRV model misses
    pedestrian_accel_sigma: float = 1.0  # m/s^2


def predict_vehicle(x: np.ndarray, P: np.ndarray, dt: float, q: MotionNoise) -> tuple[np.ndarray, np.ndarray]:
    """The CTRV prediction over ``dt`` of state ``x`` (5,) and covariance ``P`` (5, 5) (first order in dt)."""
    px, py, th, v, om = x
    c, s = math.cos(th), math.sin(th)
    xn = np.array([px + v * c * dt, py + v * s * dt, wrap(th + om * dt), v, om])
    F = vehicle_jacobian(x, dt)
    h = 0.5 * dt * dt
    G = np.array([[h * c, 0.0], [h * s, 0.0], [0.0, h], [dt, 0.0], [0.0, dt]])
    Q = G @ np.diag([q.accel_sigma ** 2, q.yaw_accel_sigma ** 2]) @ G.T
    lat = (q.lateral_sigma * dt) ** 2
    Q[0, 0] += lat * s * s
    Q[1, 1] += lat * c * c
    Q[0, 1] -= lat * s * c
    Q[1, 0] -= lat * s * c
    return xn, F @ P @ F.T + Q


def vehicle_jacobian(x: np.ndarray, dt: float) -> np.ndarray:
    """The Jacobian F (5, 5) of the CTRV prediction over ``dt`` at state ``x`` (first order in dt)."""
    th, v = float(x[2]), float(x[3])
    c, s = math.cos(th), math.sin(th)
    F = np.eye(5)
    F[0, 2], F[0, 3] = -v * s * dt, c * dt
    F[1, 2], F[1, 3] = v * c * dt, s * dt
    F[2, 4] = dt
    return F


def predict_pedestrian(x: np.ndarray, P: np.ndarray, dt: float, q: MotionNoise) -> tuple[np.ndarray, np.ndarray]:
    """The constant-velocity prediction over ``dt`` of state ``x`` (4,) and covariance ``P`` (4, 4)."""
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    h = 0.5 * dt * dt
    G = np.array([[h, 0.0], [0.0, h], [dt, 0.0], [0.0, dt]])
    return F @ x, F @ P @ F.T + G @ G.T * q.pedestrian_accel_sigma ** 2


def kalman_update(x: np.ndarray, P: np.ndarray, z: np.ndarray, H: np.ndarray, R: np.ndarray,
                  angle_rows: tuple[int, ...] = (), angle_states: tuple[int, ...] = ()
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The Kalman update of (``x``, ``P``) with measurement ``z`` = H x + noise(R); the innovation's rows
    ``angle_rows`` and the states ``angle_states`` are wrapped to [-pi, pi). Joseph form, for a covariance that
    stays symmetric and positive."""
    y = z - H @ x
    for r in angle_rows:
        y[r] = wrap(float(y[r]))
    S = H @ P @ H.T + R
    K = np.linalg.solve(S, H @ P).T  # P H^T S^-1, S symmetric
    xn = x + K @ y
    for a in angle_states:
        xn[a] = wrap(float(xn[a]))
    ImKH = np.eye(len(x)) - K @ H
    return xn, ImKH @ P @ ImKH.T + K @ R @ K.T


#: measurement matrices: a vehicle box's pose (x, y, theta), optionally with a speed; a pedestrian's position
H_POSE = np.eye(3, 5)
H_POSE_SPEED = np.vstack([np.eye(3, 5), np.eye(1, 5, 3)])
H_POSITION = np.eye(2, 4)

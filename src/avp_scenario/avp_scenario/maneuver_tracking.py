"""Time parameterisation and tracking of a maneuver's Reeds-Shepp plan with the car of eq. (1) (ROS-free):
steps 2 and 3 of :mod:`avp_scenario.maneuvers` (see its docstring for the method), and the final checks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from avp_world.geometry import wrap_angle
from avp_world.kinematics import brake_speed, step_vehicle
from avp_world.reeds_shepp import segment_end
from avp_world.vehicle import VehicleSpec

MAX_SPEED = 2.0  # m/s, ParkSim parking speed limit
MAX_ACCEL = 2.0  # m/s^2, ParkSim a_max_parking
REF_STEP = 0.01  # m between samples of the tracking reference
L_CORR = 1.0  # m: distance over which the tracker steers a lateral error away
STOP_EPS = 0.005  # m: a piece is finished when less than this is left
END_LAT_TOL, END_LON_TOL, END_HEAD_TOL = 0.15, 0.3, math.radians(3.0)  # final pose vs the spot centre


@dataclass(frozen=True)
class Piece:
    poses: np.ndarray  # (M, 3) reference poses
    kappa: np.ndarray  # (M,) signed curvature (w.r.t. signed arc length) of the path just after each pose
    s: np.ndarray  # (M,) arc length from the piece start (>= 0)
    direction: int


def pieces(start: np.ndarray, segments: tuple[tuple[str, float], ...], radius: float) -> list[Piece]:
    """Split a chained path at its cusps and sample each piece densely for tracking."""
    groups: list[list[tuple[str, float]]] = []
    for kind, ln in segments:
        d = 1 if ln > 0 else -1
        if groups and (1 if groups[-1][0][1] > 0 else -1) == d:
            groups[-1].append((kind, ln))
        else:
            groups.append([(kind, ln)])
    pieces = []
    pose = np.asarray(start, dtype=float)
    for grp in groups:
        d = 1 if grp[0][1] > 0 else -1
        poses = [pose[None]]
        kap: list[np.ndarray] = []
        arcs: list[np.ndarray] = []
        for kind, ln in grp:
            n = max(1, math.ceil(abs(ln) / REF_STEP))
            p = segment_end(pose, kind, ln * np.arange(1, n + 1) / n, radius)
            poses.append(p)
            kap.append(np.full(n, {"L": 1.0 / radius, "R": -1.0 / radius, "S": 0.0}[kind]))
            pose = p[-1]
            arcs.append(np.full(n, abs(ln) / n))  # exact arc length between samples (not the chord)
        pieces.append(
            Piece(
                poses=np.concatenate(poses),
                kappa=np.concatenate(kap + [kap[-1][-1:]]),
                s=np.concatenate([[0.0], np.cumsum(np.concatenate(arcs))]),
                direction=d,
            )
        )
    return pieces


def _project(pc: Piece, p: np.ndarray, hint: int) -> tuple[int, float, float]:
    """Nearest reference sample to point ``p`` (searched around index ``hint``): (index, progress along the
    piece in metres, lateral offset to the left of the reference heading)."""
    lo, hi = max(0, hint - 30), min(len(pc.s), hint + 80)
    diff = p[:2] - pc.poses[lo:hi, :2]
    j = lo + int(np.argmin(np.einsum("ij,ij->i", diff, diff)))
    th = pc.poses[j, 2]
    c, s = math.cos(th), math.sin(th)
    ex, ey = p[0] - pc.poses[j, 0], p[1] - pc.poses[j, 1]
    return j, float(pc.s[j] + pc.direction * (c * ex + s * ey)), -s * ex + c * ey


def track(start: np.ndarray, pieces: list[Piece], vehicle: VehicleSpec, dt: float, max_speed: float = MAX_SPEED,
           max_accel: float = MAX_ACCEL) -> np.ndarray:
    """Controls (T, 2) that drive eq. (1) along the pieces, stopping (v = 0) at the end of each.

    Speed: the largest of the discrete accelerate / cruise / brake-to-stop profile (see
    :func:`avp_world.kinematics.brake_speed`, at most ``max_speed``), never changing by more than ``max_accel``
    dt per step.
    Steering: an Euler step moves the car along its *current* heading, so the heading is set one step
    ahead: omega_k makes theta_{k+1} equal to the reference heading at the middle of step k + 1 (the chord
    direction of the reference arc there, which removes the Euler drift off curves) minus d atan(e_lat / L)
    to steer the lateral error e_lat of the already-determined position p_{k+1} back over L = 1 m; omega is
    clipped to |v| / R_min.
    """
    kmax = (1.0 / vehicle.min_turning_radius) * (1.0 - 1e-12)
    dv = max_accel * dt * (1.0 - 1e-12)
    state = np.asarray(start, dtype=float).copy()
    controls: list[tuple[float, float]] = []

    def next_speed(speed: float, rem: float) -> float:
        return max(min(max_speed, speed + dv, brake_speed(rem, dt, dv)), speed - dv, 0.0)

    for pc in pieces:
        d = pc.direction
        length = float(pc.s[-1])
        theta_u = np.unwrap(pc.poses[:, 2])
        idx = 0
        speed = 0.0
        for _ in range(100000):
            idx, sigma, _ = _project(pc, state, idx)
            rem = length - sigma
            if rem < STOP_EPS and speed <= dv:
                break
            speed = next_speed(speed, rem)
            if speed <= 1e-9:
                break
            v = d * speed
            th = state[2]
            p_next = state[:2] + v * dt * np.array([math.cos(th), math.sin(th)])
            j2, sigma2, e_lat = _project(pc, p_next, idx)
            mid = sigma2 + 0.5 * next_speed(speed, length - sigma2) * dt
            th_ref = float(np.interp(min(max(mid, 0.0), length), pc.s, theta_u))
            target = th_ref - d * math.atan(e_lat / L_CORR)
            omega = float(wrap_angle(target - th)) / dt
            lim = speed * kmax
            omega = min(max(omega, -lim), lim)
            controls.append((v, omega))
            state = step_vehicle(state, np.array([v, omega]), dt)
        else:  # pragma: no cover
            raise RuntimeError("maneuver tracking did not finish")
        controls.append((0.0, 0.0))  # stop at the cusp / at the end
        state = step_vehicle(state, np.zeros(2), dt)
    return np.array(controls, dtype=float).reshape(-1, 2)


def end_ok(final: np.ndarray, goal: np.ndarray) -> bool:
    c, s = math.cos(goal[2]), math.sin(goal[2])
    ex, ey = final[0] - goal[0], final[1] - goal[1]
    lon, lat = c * ex + s * ey, -s * ex + c * ey
    dth = abs(float(wrap_angle(final[2] - goal[2])))
    return abs(lat) <= END_LAT_TOL and abs(lon) <= END_LON_TOL and dth <= END_HEAD_TOL


def controls_ok(controls: np.ndarray, vehicle: VehicleSpec, dt: float, max_speed: float = MAX_SPEED,
                 max_accel: float = MAX_ACCEL) -> bool:
    v, om = controls[:, 0], controls[:, 1]
    acc = np.abs(np.diff(np.concatenate([[0.0], v]))) / dt
    return bool(
        (np.abs(v) <= max_speed + 1e-9).all()
        and (np.abs(om) <= np.abs(v) / vehicle.min_turning_radius + 1e-9).all()
        and (acc <= max_accel + 1e-9).all()
    )

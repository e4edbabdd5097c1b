"""From a geometric path to per-step controls (v, ω) of eq. (1) at Δt, for the planner of §V-D.

**Speed profile.** The path is split at its cusps into pieces of one driving direction. On each piece the
speed of step k is v_k = min(v_max, v_{k-1} + a_max Δt, v_brake(rem)), where v_brake is the largest speed that
still lets the car stop exactly at the end of the piece in whole steps while slowing by a_max Δt per step
(the last step covers the rest exactly). One control (0, 0) is issued at every cusp and at the end of the
path ("stop at direction switches"). A plan may start from the ego's current speed when the first piece
drives the same way.

**Reference trajectory** (:func:`reference_trajectory`): the poses reached after each step when the car
moves exactly along the path with that profile; cheap (vectorised), used to time-index candidate plans
against predictions and to price them.

**Tracking** (:func:`track`): the controls actually sent, produced while simulating eq. (1) (the idea of
``avp_scenario.maneuvers``): an Euler step moves the car along its *current* heading, so the heading is set
one step ahead: ω_k makes θ_{k+1} equal to the path heading at the middle of step k + 1 (the chord direction
of an arc) minus d atan(e_lat / L), e_lat being the lateral error of the already-determined next position
and d = ±1 the driving direction; ω is clipped to |v| / R_min. The states are ``rollout_vehicle(start,
controls, Δt)`` exactly, which is how the simulator moves the ego.
"""

from __future__ import annotations

import bisect
import functools
import math
from dataclasses import dataclass

import numpy as np

from avp_motion.settings import ControlSettings
from avp_search.paths import Path, arc_end
from avp_world.kinematics import brake_speed, rollout_vehicle

_STOP_EPS = 0.003  # m: a piece is finished when less than this is left


def piece_speeds(length: float, v0: float, settings: ControlSettings) -> np.ndarray:
    """Positive speeds per step covering ``length`` exactly (without the final stop control); read-only (the
    profiles are memoised: a decision prices the same lengths and start speed many times)."""
    return _piece_speeds(float(length), max(0.0, float(v0)), settings.dt, settings.a_max, settings.v_max)


@functools.lru_cache(maxsize=8192)
def _piece_speeds(length: float, v0: float, dt: float, a_max: float, v_max: float) -> np.ndarray:
    dv = a_max * dt * (1.0 - 1e-12)
    out: list[float] = []
    s, v = 0.0, v0
    while length - s > _STOP_EPS * 0.1:
        rem = length - s
        v = min(v_max, v + dv, brake_speed(rem, dt, dv), rem / dt)
        if v <= 1e-12:  # pragma: no cover - numerical guard
            v = rem / dt
        out.append(v)
        s += v * dt
        if len(out) > 100000:  # pragma: no cover
            raise RuntimeError("speed profile did not terminate")
    speeds = np.asarray(out, dtype=float)
    speeds.setflags(write=False)
    return speeds


@dataclass(frozen=True)
class Trajectory:
    """A time-indexed plan: ``states[k]`` is the ego pose at t + k Δt; ``controls[k]`` takes it to k + 1."""

    controls: np.ndarray  # (T, 2)
    states: np.ndarray  # (T + 1, 3)
    dt: float

    @property
    def duration(self) -> float:
        return len(self.controls) * self.dt


def _start_speed(direction: int, v0: float) -> float:
    return abs(v0) if v0 * direction > 0 else 0.0


def reference_trajectory(path: Path, settings: ControlSettings, v0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Poses (T + 1, 3) after each step when moving exactly along ``path`` with the speed profile, and the
    signed speeds (T,) of the steps (0 for the stop controls)."""
    dt = settings.dt
    poses = [np.asarray(path.start, dtype=float)[None, :]]
    speeds: list[np.ndarray] = []
    for i, piece in enumerate(path.pieces()):
        if piece.length < _STOP_EPS:  # skipped by the tracker too
            continue
        d = 1 if piece.segments[0][1] > 0 else -1
        sp = piece_speeds(piece.length, _start_speed(d, v0) if i == 0 else 0.0, settings)
        arc = np.cumsum(sp) * dt
        arc[-1] = piece.length
        p = piece.poses_at(arc)
        poses.append(p)
        poses.append(p[-1:])  # the stop control
        speeds.append(d * sp)
        speeds.append(np.zeros(1))
    out = np.concatenate(poses)
    out[0, 2] = (out[0, 2] + math.pi) % (2 * math.pi) - math.pi
    return out, np.concatenate(speeds) if speeds else np.zeros(0)


class _PieceRef:
    """Analytic reference of one piece: pose at arc length sigma (0 <= sigma <= length)."""

    def __init__(self, piece: Path):
        self.segments = piece.segments
        self.starts = piece.segment_starts()
        self.bounds = [0.0]
        for _, ell in self.segments:
            self.bounds.append(self.bounds[-1] + abs(ell))
        self.length = self.bounds[-1]
        self.direction = 1 if self.segments[0][1] > 0 else -1

    def pose(self, sigma: float) -> tuple[float, float, float]:
        sigma = min(max(sigma, 0.0), self.length)
        j = min(max(bisect.bisect_right(self.bounds, sigma) - 1, 0), len(self.segments) - 1)
        k, ell = self.segments[j]
        return arc_end(self.starts[j], k, math.copysign(sigma - self.bounds[j], ell))

    def project(self, px: float, py: float, sigma: float) -> tuple[float, float]:
        """(progress, lateral error to the left of the path heading) near the guess ``sigma`` (Newton steps)."""
        for _ in range(3):
            x, y, th = self.pose(sigma)
            c, s = math.cos(th), math.sin(th)
            lon = (px - x) * c + (py - y) * s
            sigma_new = min(max(sigma + self.direction * lon, 0.0), self.length)
            if abs(sigma_new - sigma) < 1e-7:
                sigma = sigma_new
                break
            sigma = sigma_new
        x, y, th = self.pose(sigma)
        return sigma, -(px - x) * math.sin(th) + (py - y) * math.cos(th)


def track(path: Path, settings: ControlSettings, max_curvature: float, v0: float = 0.0) -> Trajectory:
    """Controls that drive eq. (1) along ``path`` (see the module docstring) and the resulting states."""
    dt = settings.dt
    dv = settings.a_max * dt * (1.0 - 1e-12)
    kmax = max_curvature * (1.0 - 1e-12)
    lcorr = settings.lateral_correction_length
    x, y, th = (float(v) for v in path.start)
    controls: list[tuple[float, float]] = []

    def next_speed(speed: float, rem: float) -> float:
        return max(min(settings.v_max, speed + dv, brake_speed(rem, dt, dv), max(rem, 0.0) / dt), 0.0)

    for i, piece in enumerate(path.pieces()):
        ref = _PieceRef(piece)
        if ref.length < _STOP_EPS:
            continue
        d = ref.direction
        speed = _start_speed(d, v0) if i == 0 else 0.0
        sigma, _ = ref.project(x, y, 0.0)
        for _ in range(100000):
            rem = ref.length - sigma
            if rem < _STOP_EPS:
                break
            speed = next_speed(speed, rem)
            if speed <= 1e-9:
                break
            v = d * speed
            nx_, ny_ = x + v * dt * math.cos(th), y + v * dt * math.sin(th)
            sigma2, e_lat = ref.project(nx_, ny_, sigma + speed * dt)
            mid = sigma2 + 0.5 * next_speed(speed, ref.length - sigma2) * dt
            th_ref = ref.pose(mid)[2]
            target = th_ref - d * math.atan(e_lat / lcorr)
            err = (target - th + math.pi) % (2.0 * math.pi) - math.pi
            lim = speed * kmax
            omega = min(max(err / dt, -lim), lim)
            controls.append((v, omega))
            x, y, th = nx_, ny_, th + omega * dt
            sigma = sigma2
        else:  # pragma: no cover
            raise RuntimeError("tracking did not finish")
        controls.append((0.0, 0.0))  # stop at the cusp / at the end
    ctrl = np.array(controls, dtype=float).reshape(-1, 2)
    states = rollout_vehicle(np.asarray(path.start, dtype=float), ctrl, dt)
    return Trajectory(controls=ctrl, states=states, dt=dt)

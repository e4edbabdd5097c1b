"""One track: its filter state, its life (hits, misses, confirmation) and the pose history it gives the ego."""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from avp_tracking.core.motion import wrap


@dataclass
class Track:
    """A vehicle track (state x, y, theta, v, omega) or a pedestrian track (state x, y, vx, vy)."""

    id: int
    pedestrian: bool
    x: np.ndarray
    P: np.ndarray
    born_step: int
    length: float = 0.0  # a vehicle's box, smoothed over its detections
    width: float = 0.0
    radius: float = 0.0  # a pedestrian's
    existence: float = 0.5
    hits: int = 1
    misses: int = 0  # steps since the last detection
    last_step: int = 0  # the step of the last detection
    confirmed: bool = False
    flip_votes: float = 0.0  # > 0: detections say the heading is turned by pi
    history: deque = field(default_factory=deque)  # (step, pose (3,)) of each step since birth, oldest first
    previous_position: np.ndarray | None = None  # a pedestrian's estimate one step before
    stationary: bool = False  # held still (tracker.Tracker._stationarity)
    slow_since: int | None = None  # the step since which it has been slower than static_speed
    jumps: int = 0  # detections in a row that say a stationary track moves (Tracker._stationarity)
    held: np.ndarray | None = None  # (x, y, theta, length, width) given while stationary (Tracker._hold)
    near_held: bool = False  # unseen beyond max_coast, kept standing near the ego (guards.keep_near)
    filter_steps: deque = field(default_factory=deque)  # the filter's last steps, to smooth the history (smoother)
    born_position: np.ndarray | None = None  # a vehicle's estimate at birth (tracking.static_until_moved)
    moved: bool = False  # its estimate has been static_until_moved or more from there (perceive)

    @property
    def position(self) -> np.ndarray:
        return self.x[:2]

    @property
    def pose(self) -> np.ndarray:
        """(x, y, theta) given to the ego: the held pose of a stationary vehicle track, else the estimate; a
        pedestrian's theta is its direction of motion (0 standing)."""
        if self.held is not None:
            return self.held[:3].copy()
        if not self.pedestrian:
            return self.x[:3].copy()
        vx, vy = self.x[2], self.x[3]
        return np.array([self.x[0], self.x[1], math.atan2(vy, vx) if vx * vx + vy * vy > 1e-6 else 0.0])

    @property
    def dims(self) -> tuple[float, float]:
        """(length, width) given to the ego: the held box of a stationary vehicle track, else the smoothed one."""
        if self.held is not None:
            return float(self.held[3]), float(self.held[4])
        return float(self.length), float(self.width)

    @property
    def speed(self) -> float:
        return float(self.x[3]) if not self.pedestrian else float(math.hypot(self.x[2], self.x[3]))

    def record(self, step: int, keep: int) -> None:
        """Append this step's estimate to the history (``keep`` poses at most)."""
        self.history.append((step, self.pose))
        while len(self.history) > keep:
            self.history.popleft()

    def history_array(self) -> np.ndarray:
        """(H, 3) poses, oldest first, the last the current estimate."""
        return np.array([p for _, p in self.history], dtype=float).reshape(-1, 3)

    def turn_around(self) -> None:
        """Resolve a heading flip: the track's heading was the box's other end all along (theta + pi, v -> -v);
        its history turns with it."""
        self.x[2] = wrap(float(self.x[2]) + math.pi)
        self.x[3] = -self.x[3]
        self.flip_votes = 0.0
        self.held = None
        self.filter_steps.clear()  # estimates of the other heading: nothing to smooth with
        self.history = deque((s, np.array([p[0], p[1], wrap(float(p[2]) + math.pi)])) for s, p in self.history)

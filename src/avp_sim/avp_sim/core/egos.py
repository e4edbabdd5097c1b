"""The automated cars of one episode: K egos, each with its own pose, status and §VI-B metrics (docs/world.md,
"Several egos").

The paper has one ego (K = 1, the default). With K > 1 (``egos.count``) the egos enter through the scenario's gate one
after another, ``egos.entry_interval`` seconds apart, each as soon as its time has come and the gate is clear (no
vehicle or other ego overlaps the start pose). To each other an ego is an ordinary observed vehicle, with the id
``EGO_ID_BASE + i`` and the last t_hist of its poses as history — never its plan or chosen spot. An ego that has
parked (or collided) stays where it is: a parked car (a wreck) for everyone. Departures from the one-ego text, each
named: §III-B's reactive agents brake for every ego present; an ego's parking time counts from its entry.

Driven cars (``drivers.count``, docs/teleop.md): D more slots after the K egos, cars a person drives from outside
(``/avp/driver<j>/cmd_vel``). They enter through the gate at ``drivers.enter_at`` (and every ``egos.entry_interval``
after), are ordinary observed vehicles to every ego, agents brake for them as for an ego, and the episode never waits
for them: it ends when the egos' episodes have.
"""

from __future__ import annotations

import numpy as np

from avp_sim.core.metrics import RUNNING, EpisodeMetrics
from avp_world.geometry import rect_corners

#: the id an ego has in the other egos' observations and in collision records (``vehicle:<id>`` -> ``ego:<i>``)
EGO_ID_BASE = 900_000


class Egos:
    """Poses, histories, entry and per-ego metrics of K egos (read by :class:`~avp_sim.core.world.World`)."""

    def __init__(self, start: np.ndarray, count: int, entry_steps: int, hist: int, length: float, width: float,
                 entries: tuple = (), drivers: int = 0, driver_step: int = 0, driver_poses: tuple = ()):
        """Ego 0 starts at ``start`` at t = 0. Egos 1..K-1 enter at ``start`` every ``entry_steps`` steps, or, where
        a scenario gives ``entries`` ((pose, step) for each of them; K is then 1 + their number), there and then.
        ``drivers`` driven cars follow in slots K..K+D-1, entering at ``start`` (or at ``driver_poses[j]``) from step
        ``driver_step`` on, one every ``entry_steps``."""
        count = 1 + len(entries) if entries else count
        if count < 1:
            raise ValueError(f"egos.count must be >= 1, got {count}")
        self.n_auto = count  # K: the automated cars (each with a pipeline)
        self.drivers = int(drivers)
        count += self.drivers
        self.count = count  # K + D slots
        self.length, self.width = float(length), float(width)
        self.starts = np.repeat(np.asarray(start, dtype=float)[None], count, axis=0)
        self.due_step = np.arange(count, dtype=np.int64) * int(entry_steps)  # when each may enter
        for i, (pose, step) in enumerate(entries, start=1):
            self.starts[i], self.due_step[i] = pose, step
        for j in range(self.drivers):
            self.due_step[self.n_auto + j] = int(driver_step) + j * int(entry_steps)
            if j < len(driver_poses):
                self.starts[self.n_auto + j] = driver_poses[j]
        self.is_driver = np.arange(count) >= self.n_auto
        self.poses = self.starts.copy()
        self.speeds = np.zeros(count)
        self.entered_step = np.full(count, -1, dtype=np.int64)
        self.entered_step[0] = 0
        self.present = np.zeros(count, dtype=bool)  # in the lot: entered (and then parked, crashed or driving)
        self.present[0] = True
        self.status = [RUNNING] * count
        self.metrics = [EpisodeMetrics() for _ in range(count)]
        self.history = np.repeat(self.poses[:, None], hist + 1, axis=1)  # (K, hist + 1, 3) as the agents' buffer

    @property
    def driving(self) -> np.ndarray:
        """(K,) egos in the lot whose episode is still running (they take commands)."""
        return self.present & np.array([s == RUNNING for s in self.status])

    def corners(self, rows: np.ndarray | None = None) -> np.ndarray:
        rows = np.arange(self.count) if rows is None else rows
        return rect_corners(self.poses[rows], self.length, self.width).reshape(len(rows), 4, 2)

    def others(self, i: int) -> np.ndarray:
        """Rows of the egos in the lot other than ``i``."""
        rows = np.nonzero(self.present)[0]
        return rows[rows != i]

    def push_history(self) -> None:
        self.history = np.concatenate([self.history[:, 1:], self.poses[:, None]], axis=1)

    def waiting(self) -> np.ndarray:
        """Rows of the egos not in the lot yet, by entry time."""
        rows = np.nonzero(~self.present & (self.entered_step < 0))[0]
        return rows[np.argsort(self.due_step[rows], kind="stable")]

    def enter(self, i: int, step: int) -> None:
        self.present[i] = True
        self.entered_step[i] = step
        self.poses[i] = self.starts[i]
        self.history[i] = self.starts[i]

    def ego_name(self, who: str) -> str:
        """``vehicle:<EGO_ID_BASE + j>`` -> ``ego:<j>``, or ``driver:<j - K>`` for a driven car (a collision record)."""
        kind, _, ident = who.partition(":")
        if kind == "vehicle" and ident.isdigit() and int(ident) >= EGO_ID_BASE:
            j = int(ident) - EGO_ID_BASE
            return f"driver:{j - self.n_auto}" if j >= self.n_auto else f"ego:{j}"
        return who

"""Spot readings filtered over time: a spot's status as the ego reports it is its evidence's, not one step's reading
(docs/perception.md, "Tracking").

A noisy sensor misreads a spot with a probability that grows with range (``sensing.spot_misread_far`` x (r/R)^2,
Nawaz et al.'s accuracy model). The paper's eq. (7) sets a spot's belief to each step's reading, so one misread
turns a vacant spot far away into an obstacle, or an occupied one into a candidate, for that step — and the
planner's static world changes with it. Here each spot keeps the log-odds of "occupied" over its readings, each
reading weighted by its error probability at its range (a binary Bayes filter, as an occupancy grid's cells are
updated), clamped to +-``max_log_odds`` so a spot whose status really changes (a car parks, or leaves) is followed
within a few readings. A spot seen this step is reported occupied if its log-odds are positive, vacant if not; a
spot not seen is not reported (as before). With ``misread_far`` 0 the readings pass through unchanged.
"""

from __future__ import annotations

import numpy as np


class SpotFilter:
    """Log-odds of each spot's occupancy over its readings; :meth:`update` once a step."""

    def __init__(self, spot_ids, spot_xy: np.ndarray, misread_far: float, reach: float,
                 max_log_odds: float = 8.0, min_error: float = 1e-3):
        self.misread_far = float(misread_far)
        self.reach = max(float(reach), 1e-6)
        self.max_log_odds = float(max_log_odds)
        self.min_error = float(min_error)
        self.xy = np.asarray(spot_xy, dtype=float).reshape(-1, 2)
        self.row = {int(s): k for k, s in enumerate(np.asarray(spot_ids, dtype=np.int64).tolist())}
        self.log_odds = np.zeros(len(self.row))

    def reset(self) -> None:
        self.log_odds[:] = 0.0

    def error(self, r: np.ndarray) -> np.ndarray:
        """A reading's misread probability at range ``r`` (the sensor's model), at least ``min_error``."""
        e = self.misread_far * np.minimum(np.asarray(r, float) / self.reach, 1.0) ** 2
        return np.clip(e, self.min_error, 0.5 - 1e-9)

    def update(self, ego_xy, vacant_ids, occupied_ids) -> tuple[np.ndarray, np.ndarray]:
        """Take this step's readings; returns (vacant ids, occupied ids) of the spots seen, by their evidence."""
        vac = np.asarray(vacant_ids, dtype=np.int64).reshape(-1)
        occ = np.asarray(occupied_ids, dtype=np.int64).reshape(-1)
        if self.misread_far <= 0 or not (len(vac) + len(occ)):
            return vac, occ
        ids = np.concatenate([vac, occ])
        rows = np.fromiter((self.row[int(s)] for s in ids), dtype=np.int64, count=len(ids))
        sign = np.r_[-np.ones(len(vac)), np.ones(len(occ))]
        r = np.hypot(*(self.xy[rows] - np.asarray(ego_xy, float)[:2]).T)
        e = self.error(r)
        lo = self.log_odds[rows] + sign * np.log((1.0 - e) / e)
        self.log_odds[rows] = np.clip(lo, -self.max_log_odds, self.max_log_odds)
        occupied = self.log_odds[rows] > 0.0
        return np.sort(ids[~occupied]), np.sort(ids[occupied])

"""The ego's recent poses (t_hist of §III-A) for the ego's trail in the reconstructed BEVs (§V-B).

Shared by the belief node's core (:class:`~avp_perception.core.pipeline.PerceptionCore`) and the learned trajectory
predictor (:class:`~avp_predictors.learned_prediction.LearnedPredictor`), which both draw BEVs.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from avp_world.types import Observation


class EgoTrail:
    """Ego poses over the last ``t_hist`` seconds, oldest first, one :meth:`update` per observation.

    A re-sent observation (the same step again) replaces the newest pose instead of adding one; an observation
    from an earlier step (:meth:`went_back`: a new episode) is the caller's cue to reset its own state and
    :meth:`clear` the trail.
    """

    def __init__(self, t_hist: float):
        self.t_hist = float(t_hist)
        self._poses: deque[np.ndarray] = deque()
        self.last_step = -1

    def clear(self) -> None:
        self._poses.clear()
        self.last_step = -1

    def went_back(self, obs: Observation) -> bool:
        """Time went back (a new episode)."""
        return obs.step < self.last_step

    def repeats(self, obs: Observation) -> bool:
        """``obs`` is the newest step's observation again (re-sent)."""
        return obs.step == self.last_step and bool(self._poses)

    def update(self, obs: Observation) -> np.ndarray:
        """Add ``obs.ego_pose``; returns the (H, 3) poses over the last t_hist ending with it."""
        if self.repeats(obs):
            self._poses.pop()
        self.last_step = obs.step
        self._poses.append(np.asarray(obs.ego_pose, dtype=float).copy())
        keep = int(round(self.t_hist / obs.dt)) + 1 if obs.dt > 0 else 1
        while len(self._poses) > keep:
            self._poses.popleft()
        return np.array(self._poses)

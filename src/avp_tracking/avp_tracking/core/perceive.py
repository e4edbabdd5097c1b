"""From a noisy sensor's frame to the observation the ego's pipeline reads: the tracker's tracks in place of the
simulator's vehicles and pedestrians (docs/perception.md, "Tracking").

What reaches the belief node, the prediction node and the planner is an :class:`~avp_world.types.Observation` as
before, with every vehicle a confirmed track (its id the tracker's, its history the tracker's own estimates, at most
``history_steps`` of them, shorter for a young track), every pedestrian a track, and the ego's pose the localisation
estimate. A track is static (parked: the paper's K_sv) when its centre lies in a spot and it moves slower than
``static_speed``, the simulator's rule applied to the estimate. The spots seen are reported by their evidence over
time (:mod:`.spots`), not by this step's reading alone.
"""

from __future__ import annotations

import math

import numpy as np

from avp_tracking.core.guards import grown_dims
from avp_tracking.core.smoother import history_smoothed
from avp_tracking.core.spots import SpotFilter
from avp_tracking.core.tracker import Tracker
from avp_world.detections import SensedFrame
from avp_world.types import Observation, ObservedPedestrian, ObservedVehicle


class SpotTest:
    """Whether points lie inside a spot of a lot (each spot's rectangle)."""

    def __init__(self, lot):
        self.poses = np.asarray(lot.spot_poses, dtype=float).reshape(-1, 3)
        self.half = 0.5 * np.asarray(lot.spot_dims, dtype=float).reshape(-1, 2)
        self.c, self.s = np.cos(self.poses[:, 2]), np.sin(self.poses[:, 2])

    def inside(self, xy: np.ndarray) -> bool:
        if not len(self.poses):
            return False
        d = np.asarray(xy, dtype=float)[:2] - self.poses[:, :2]
        u = d[:, 0] * self.c + d[:, 1] * self.s
        w = -d[:, 0] * self.s + d[:, 1] * self.c
        return bool(((np.abs(u) <= self.half[:, 0]) & (np.abs(w) <= self.half[:, 1])).any())


class TrackingPerception:
    """The tracker and the conversion of its tracks, one ego's; :meth:`observe` once a step."""

    def __init__(self, lot, tracker: Tracker):
        self.tracker = tracker
        self.spots = SpotTest(lot)
        self._lot = lot
        self.spot_filter = self._spot_filter()

    def _spot_filter(self) -> SpotFilter:
        c = self.tracker.cfg
        return SpotFilter(self._lot.spot_ids, np.asarray(self._lot.spot_poses, float).reshape(-1, 3)[:, :2],
                          c.spot_misread_far, c.spot_reach, c.spot_max_log_odds)

    def _history(self, t) -> np.ndarray:
        """The pose history given with vehicle track ``t``: the tracker's estimates, the last ``smoothing_lag`` of a
        moving track smoothed with ``history_smoothing`` rts (:mod:`.smoother`)."""
        if self.tracker.cfg.history_smoothing == "rts" and not t.stationary and t.filter_steps:
            return history_smoothed(t.history, t.filter_steps)
        return t.history_array()

    def _previous(self, t, dt: float) -> np.ndarray:
        """The previous position given with pedestrian track ``t`` (the ego reads its velocity from the two,
        §V-C): its estimate one step before, or with ``pedestrian_velocity`` "filter" its estimate minus the
        filter's velocity times dt — a standing pedestrian's estimate jumps by centimetres each step, which the
        difference reads as walking (0.55 m/s median at 0.15 m detection noise; the filter's velocity 0.15)."""
        if self.tracker.cfg.pedestrian_velocity == "filter":
            return t.x[:2] - t.x[2:4] * dt
        return (t.previous_position if t.previous_position is not None else t.x[:2]).copy()

    def _is_static(self, t) -> bool:
        """A vehicle track given as static (a parked car: no intentions, no prediction, §V-A): slower than
        ``static_speed`` and inside a spot. With ``static_until_moved`` > 0, a track inside a spot is static too until
        its estimate has once been that far from where it was born: a parked car newly seen starts with a noisy
        speed, and as a moving car next to a free spot the intent CNN reads it as about to park there."""
        cfg = self.tracker.cfg
        if not self.spots.inside(t.x[:2]):
            return False
        if abs(t.speed) < cfg.static_speed:
            return True
        if cfg.static_until_moved <= 0 or t.born_position is None:
            return False
        t.moved = t.moved or math.hypot(*(t.x[:2] - t.born_position)) >= cfg.static_until_moved
        return not t.moved

    def observe(self, frame: SensedFrame) -> Observation:
        new_episode = self.tracker.step is None or frame.step < self.tracker.step  # as the tracker resets itself
        tracks = self.tracker.update(frame)
        c, f = self.tracker.cfg, self.spot_filter
        if (f.misread_far, f.reach, f.max_log_odds) != (c.spot_misread_far, c.spot_reach, c.spot_max_log_odds):
            self.spot_filter = f = self._spot_filter()  # the node's parameters changed
        elif new_episode:
            f.reset()
        vacant, occupied = f.update(frame.ego_pose, frame.vacant_spot_ids, frame.occupied_spot_ids)
        sigmas = self.tracker.cfg.box_sigmas
        vehicles = tuple(
            ObservedVehicle(id=int(t.id), length=dims[0], width=dims[1], is_static=self._is_static(t),
                            history=self._history(t))
            for t in tracks if not t.pedestrian for dims in (grown_dims(t, sigmas),))
        peds = tuple(ObservedPedestrian(int(t.id), float(t.radius), t.x[:2].copy(), self._previous(t, frame.dt))
                     for t in tracks if t.pedestrian)
        return Observation(step=frame.step, dt=frame.dt, ego_pose=np.asarray(frame.ego_pose, float).copy(),
                           ego_length=frame.ego_length, ego_width=frame.ego_width, ego_speed=frame.ego_speed,
                           vacant_spot_ids=np.asarray(vacant, np.int64),
                           occupied_spot_ids=np.asarray(occupied, np.int64),
                           vehicles=vehicles, pedestrians=peds, ray_angle_min=frame.ray_angle_min,
                           ray_angle_increment=frame.ray_angle_increment, ray_ranges=frame.ray_ranges,
                           ego_covariance=np.asarray(frame.ego_covariance, float).copy())

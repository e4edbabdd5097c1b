"""The multi-object tracker (docs/perception.md, "Tracking"): detections of one step, with no ids, in; tracks with
persistent ids, a state with covariance and the pose history the intent CNN, the BEV and the predictors read, out.

Each step (:meth:`Tracker.update`): every track is predicted to the frame's time (:mod:`.motion`); vehicles and
pedestrians are associated apart by gated global nearest neighbour (:mod:`.association`); a matched track is
updated (its heading measured modulo a flip, below); an unmatched detection starts a *tentative* track, which is
*confirmed* after ``n_init`` hits and dropped at its first miss before that; a confirmed track that goes unseen is
coasted (predicted, its history continued with the predictions; with ``coast_deceleration`` its speed brakes to a
stop meanwhile) and dropped after ``max_coast`` seconds — unless, with ``near_hold_radius``, it is near the ego and
kept standing a while (:mod:`.guards`).

Heading flips: a detection whose heading differs from the track's by more than 90 degrees is taken as the box's
other end (a car cannot turn that much in one step) and measured turned by pi; each such detection adds a vote,
each agreeing one takes one away, and at ``flip_votes`` votes the track itself turns around
(:meth:`~.tracks.Track.turn_around`): a track born from a flipped box is set right within a few steps, while the
rare flipped box on a good track changes nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from avp_tracking.core.association import gated_pairs
from avp_tracking.core.guards import keep_near
from avp_tracking.core.motion import (
    H_POSE,
    H_POSE_SPEED,
    H_POSITION,
    MotionNoise,
    kalman_update,
    predict_pedestrian,
    predict_vehicle,
    vehicle_jacobian,
    wrap,
)
from avp_tracking.core.smoother import remember
from avp_tracking.core.tracks import Track
from avp_world.detections import ORIENTATION_AVAILABLE, PedestrianDetection, SensedFrame, VehicleDetection


@dataclass(frozen=True)
class TrackerConfig:
    """The tracker's settings (tracking.* of config/tracker.param.yaml)."""

    gate: float = 11.62  # squared Mahalanobis gate of a pairing (chi-square, 2 dof, 99.7 %)
    max_distance: float = 3.0  # m, a vehicle pairing's largest centre distance
    pedestrian_max_distance: float = 1.5  # m
    n_init: int = 3  # hits that confirm a track
    max_coast: float = 1.5  # s a confirmed track lives unseen
    coast_deceleration: float = 0.0  # m/s^2: an unseen vehicle track's speed brakes to 0 at this rate; 0 = off
    flip_votes: float = 3.0  # votes that turn a track around
    size_smoothing: float = 0.2  # weight of a new box's length and width
    history_steps: int = 41  # poses of history a track gives (t_hist / dt + 1)
    static_speed: float = 0.3  # m/s: a track standing in a spot slower than this is static (parked)
    publish_coasted: bool = True  # coasted confirmed tracks are given to the ego (else only those seen now)
    noise: MotionNoise = field(default_factory=MotionNoise)
    init_speed_sigma: float = 3.0  # m/s, a new vehicle track's speed spread without a speed estimate
    init_yaw_rate_sigma: float = 0.5  # rad/s
    prune_distance: float = 1.5  # m: of two vehicle tracks closer than this (headings within 30 deg), one is dropped
    stationary_after: float = 1.0  # s a vehicle track stays slower than static_speed before it is held stationary
    stationary_noise_scale: float = 0.05  # a stationary track's process noise, times the moving one's
    stationary_hold: float = 0.1  # m: a stationary track's given pose and box change only by more than this; 0 = off
    stationary_hold_heading: float = 0.05  # rad: the same for its heading
    spot_misread_far: float = 0.05  # a spot reading's error probability at spot_reach (the sensor's model); 0 = off
    spot_reach: float = 11.5  # m, the range at which a reading's error is spot_misread_far (it grows as range^2)
    spot_max_log_odds: float = 8.0  # a spot's evidence is clamped to +- this (a real change is followed)
    near_hold_radius: float = 0.0  # m: a dropped track this near the ego is kept standing (.guards); 0 = off
    near_hold_max: float = 10.0  # s at most such a track is kept beyond max_coast
    box_sigmas: float = 0.0  # a moving track's box grows by this many position sigmas at each side (.guards); 0 = off
    pedestrian_velocity: str = "difference"  # a pedestrian's previous position: last estimate, or "filter" (.perceive)
    history_smoothing: str = "none"  # "rts": a moving vehicle track's last smoothing_lag poses smoothed (.smoother)
    smoothing_lag: int = 10  # steps
    static_until_moved: float = 0.0  # m: a vehicle track in a spot is given as static until it moved this far; 0 = off


class Tracker:
    """Tracks of one ego (module docstring). Same detections in the same order give the same tracks."""

    def __init__(self, config: TrackerConfig | None = None):
        self.cfg = config or TrackerConfig()
        self.tracks: list[Track] = []
        self.tracks_given: list[Track] = []
        self.next_id = 1
        self.step: int | None = None
        self._dt = 0.1

    def reset(self) -> None:
        self.tracks, self.tracks_given, self.next_id, self.step = [], [], 1, None

    def update(self, frame: SensedFrame) -> list[Track]:
        """Take one step's detections; returns the tracks to give the ego (confirmed; coasted ones with
        ``publish_coasted``)."""
        cfg = self.cfg
        dt = frame.dt * (frame.step - self.step) if self.step is not None else 0.0
        if dt < 0:  # a new episode (the step went back): start again
            self.reset()
            dt = 0.0
        self.step = frame.step
        self._dt = frame.dt
        if dt > 0:
            quiet = _scaled(cfg.noise, cfg.stationary_noise_scale)
            for t in self.tracks:
                t.previous_position = t.x[:2].copy() if t.pedestrian else None
                predict = predict_pedestrian if t.pedestrian else predict_vehicle
                if t.stationary or t.near_held:  # held still: a constant-position model (speed, yaw rate 0)
                    t.x[3] = t.x[4] = 0.0
                elif t.misses and cfg.coast_deceleration > 0 and not t.pedestrian:
                    # unseen since the last step: a car hidden near the ego is as likely to stop as to go on
                    v = float(t.x[3])
                    t.x[3] = math.copysign(max(0.0, abs(v) - cfg.coast_deceleration * dt), v)
                F = vehicle_jacobian(t.x, dt) if t.filter_steps else None
                t.x, t.P = predict(t.x, t.P, dt, quiet if t.stationary or t.near_held else cfg.noise)
                if F is not None:  # links the last remembered step to this one (.smoother)
                    last = t.filter_steps[-1]
                    last.F, last.x_next, last.P_next = F, t.x.copy(), t.P.copy()
        vehicles = [t for t in self.tracks if not t.pedestrian]
        peds = [t for t in self.tracks if t.pedestrian]
        seen: set[int] = set()
        for tracks, dets, gate_d in ((vehicles, frame.vehicles, cfg.max_distance),
                                     (peds, frame.pedestrians, cfg.pedestrian_max_distance)):
            pairs = self._associate(tracks, dets, gate_d)
            matched = set()
            for ti, di in pairs:
                self._correct(tracks[ti], dets[di], frame.step)
                seen.add(tracks[ti].id)
                matched.add(di)
            for di, d in enumerate(dets):
                if di not in matched:
                    self.tracks.append(self._birth(d, frame.step))
                    seen.add(self.tracks[-1].id)
        keep = []
        max_misses = max(1, int(round(cfg.max_coast / frame.dt))) if frame.dt > 0 else 1
        for t in self.tracks:
            if t.id not in seen:
                t.misses += 1
                if not t.confirmed:
                    continue
                if t.misses > max_misses:
                    t.near_held = keep_near(t, frame, max_misses, cfg.near_hold_radius, cfg.near_hold_max)
                    if not t.near_held:
                        continue
            keep.append(t)
            t.record(frame.step, cfg.history_steps)
            if cfg.history_smoothing == "rts" and not t.pedestrian:
                remember(t.filter_steps, frame.step, t.x, t.P, cfg.smoothing_lag)
        self.tracks = self._prune(keep)
        #: what the last update gave the ego
        self.tracks_given = [t for t in self.tracks if t.confirmed and (cfg.publish_coasted or t.misses == 0)]
        return self.tracks_given

    def _prune(self, tracks: list[Track]) -> list[Track]:
        """Drop duplicates (as Autoware's overlap pruning): of two vehicle tracks whose centres are closer than
        ``prune_distance`` and whose axes agree within 30 degrees, the one with fewer hits (then the younger) goes —
        two tracks sharing one car's detections step by step would both live on, one of them a ghost beside it."""
        cars = [t for t in tracks if not t.pedestrian]
        if len(cars) < 2 or self.cfg.prune_distance <= 0:
            return tracks
        order = sorted(cars, key=lambda t: (-int(t.confirmed), -t.hits, t.born_step, t.id))
        kept: list[Track] = []
        for t in order:
            if any(math.hypot(t.x[0] - k.x[0], t.x[1] - k.x[1]) < self.cfg.prune_distance
                   and abs(math.remainder(float(t.x[2] - k.x[2]), math.pi)) < math.radians(30.0) for k in kept):
                continue
            kept.append(t)
        alive = {id(t) for t in kept}
        return [t for t in tracks if t.pedestrian or id(t) in alive]

    def _associate(self, tracks: list[Track], dets, max_distance: float) -> list[tuple[int, int]]:
        if not tracks or not dets:
            return []
        txy = np.array([t.x[:2] for t in tracks])
        tcov = np.array([t.P[:2, :2] for t in tracks])
        if isinstance(dets[0], VehicleDetection):
            dxy = np.array([d.pose[:2] for d in dets])
        else:
            dxy = np.array([d.position for d in dets])
        dcov = np.array([np.asarray(d.covariance)[:2, :2] for d in dets])
        return gated_pairs(txy, tcov, dxy, dcov, self.cfg.gate, max_distance)

    def _correct(self, t: Track, d, step: int) -> None:
        cfg = self.cfg
        t.hits += 1
        t.misses = 0
        t.near_held = False
        t.last_step = step
        t.existence = 0.7 * t.existence + 0.3 * float(d.existence)
        if t.hits >= cfg.n_init:
            t.confirmed = True
        if t.pedestrian:
            t.x, t.P = kalman_update(t.x, t.P, np.asarray(d.position, float), H_POSITION,
                                     np.asarray(d.covariance, float)[:2, :2])
            t.radius = 0.8 * t.radius + 0.2 * float(d.radius)
            return
        z_th = float(d.pose[2])
        flipped = abs(wrap(z_th - float(t.x[2]))) > 0.5 * math.pi
        if d.orientation == ORIENTATION_AVAILABLE:
            t.flip_votes = min(cfg.flip_votes, t.flip_votes + 1.0) if flipped else max(-cfg.flip_votes,
                                                                                         t.flip_votes - 1.0)
        if t.flip_votes >= cfg.flip_votes:  # the detections agree on the other end: the track turns around
            t.turn_around()
            flipped = not flipped
        z_th = wrap(z_th + math.pi) if flipped else z_th
        R = np.asarray(d.covariance, float)[:3, :3].copy()
        if math.isfinite(d.speed):
            z = np.array([d.pose[0], d.pose[1], z_th, -d.speed if flipped else d.speed])
            Rz = np.zeros((4, 4))
            Rz[:3, :3] = R
            Rz[3, 3] = d.speed_variance if math.isfinite(d.speed_variance) else 1.0
            t.x, t.P = kalman_update(t.x, t.P, z, H_POSE_SPEED, Rz, angle_rows=(2,), angle_states=(2,))
        else:
            z = np.array([d.pose[0], d.pose[1], z_th])
            t.x, t.P = kalman_update(t.x, t.P, z, H_POSE, R, angle_rows=(2,), angle_states=(2,))
        a = cfg.size_smoothing
        t.length = (1 - a) * t.length + a * float(d.length)
        t.width = (1 - a) * t.width + a * float(d.width)
        self._stationarity(t, d, step)

    def _stationarity(self, t: Track, d, step: int) -> None:
        """A vehicle track that has been slower than ``static_speed`` for ``stationary_after`` s is held stationary:
        its speed and yaw rate are set to 0 before each prediction and its process noise is scaled by
        ``stationary_noise_scale`` (a parked car's box stops jittering with each detection's noise). Two detections
        in a row that say it moves — beyond half the gate from it, or a measured speed above ``static_speed`` by
        two of its standard deviations (one alone comes with the detections' noise a few times in 100 steps) — or
        an estimated speed above ``static_speed`` let it move again at once, its speed spread reset to a new
        track's."""
        cfg = self.cfg
        slow = abs(float(t.x[3])) < cfg.static_speed
        S = t.P[:2, :2] + np.asarray(d.covariance, float)[:2, :2]
        r = np.asarray(d.pose[:2], float) - t.x[:2]
        fast = (math.isfinite(d.speed) and math.isfinite(d.speed_variance)
                and abs(float(d.speed)) > cfg.static_speed + 2.0 * math.sqrt(max(float(d.speed_variance), 0.0)))
        t.jumps = t.jumps + 1 if fast or float(r @ np.linalg.solve(S, r)) > 0.5 * cfg.gate else 0
        if not slow or t.jumps >= 2:
            if t.stationary:
                t.P[3, 3] = max(float(t.P[3, 3]), cfg.init_speed_sigma ** 2)
            t.slow_since, t.stationary, t.held, t.jumps = None, False, None, 0
            return
        if t.slow_since is None:
            t.slow_since = step
        t.stationary = (step - t.slow_since) * self._dt >= cfg.stationary_after
        self._hold(t)

    def _hold(self, t: Track) -> None:
        """A stationary track gives the ego a held pose and box, renewed from the estimate only when the estimate
        has left it by more than ``stationary_hold`` (m; the box's length or width as well) or
        ``stationary_hold_heading`` (rad). A parked car's estimate still moves by millimetres with each detection
        and with the ego's localisation; held, the planner's static world stays the same step after step (and its
        cached maps and searches with it) while the car stands."""
        cfg = self.cfg
        if not t.stationary or cfg.stationary_hold <= 0:
            t.held = None
            return
        h = t.held
        if (h is None or math.hypot(t.x[0] - h[0], t.x[1] - h[1]) > cfg.stationary_hold
                or abs(wrap(float(t.x[2] - h[2]))) > cfg.stationary_hold_heading
                or abs(t.length - h[3]) > cfg.stationary_hold or abs(t.width - h[4]) > cfg.stationary_hold):
            t.held = np.array([t.x[0], t.x[1], wrap(float(t.x[2])), t.length, t.width])

    def _birth(self, d, step: int) -> Track:
        cfg = self.cfg
        tid, self.next_id = self.next_id, self.next_id + 1
        if isinstance(d, PedestrianDetection):
            x = np.array([d.position[0], d.position[1], 0.0, 0.0])
            P = np.diag([*np.diag(np.asarray(d.covariance, float))[:2], 1.0, 1.0])
            return Track(id=tid, pedestrian=True, x=x, P=P, born_step=step, radius=float(d.radius),
                         existence=float(d.existence), last_step=step, confirmed=cfg.n_init <= 1,
                         previous_position=x[:2].copy())
        v = float(d.speed) if math.isfinite(d.speed) else 0.0
        sv = math.sqrt(d.speed_variance) if math.isfinite(d.speed) and math.isfinite(d.speed_variance) \
            else cfg.init_speed_sigma
        cov = np.asarray(d.covariance, float)
        P = np.zeros((5, 5))
        P[:3, :3] = cov[:3, :3]
        P[3, 3], P[4, 4] = sv * sv, cfg.init_yaw_rate_sigma ** 2
        x = np.array([d.pose[0], d.pose[1], wrap(float(d.pose[2])), v, 0.0])
        return Track(id=tid, pedestrian=False, x=x, P=P, born_step=step, length=float(d.length),
                     width=float(d.width), existence=float(d.existence), last_step=step,
                     confirmed=cfg.n_init <= 1, born_position=x[:2].copy())


def _scaled(q: MotionNoise, k: float) -> MotionNoise:
    """``q`` with every spread times sqrt(k) (variances times k)."""
    from dataclasses import replace

    r = k ** 0.5
    return replace(q, accel_sigma=q.accel_sigma * r, yaw_accel_sigma=q.yaw_accel_sigma * r,
                   lateral_sigma=q.lateral_sigma * r, pedestrian_accel_sigma=q.pedestrian_accel_sigma * r)

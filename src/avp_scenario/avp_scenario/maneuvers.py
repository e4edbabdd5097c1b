"""ParkSim's library of 8 parking maneuvers, re-made for the car of eq. (1) (ROS-free).

ParkSim (``path_planner/hobca_planner.py``, ``offline_maneuver.py``) stores an offline library of parking
maneuvers in a canonical scene: an aisle along x, the target spot centred at x = 0 on one side of it, the
car stopped in the right half of the aisle, driving east. The 8 entries are

    side  in {near, far}:         target spot on the car's right (ParkSim "south") or across the aisle
                                   ("north");
    stop  in {before, after}:     the car waits at x0 = -4 m (before the spot, ParkSim "left") or +4 m
                                   (after it, overshooting, ParkSim "right");
    entry in {head_in, tail_in}:  it ends nose first (heading = spot heading) or reversed in (+ pi).

ParkSim solves each with H-OBCA (Hybrid A* warm start + IPOPT) on an RK4 kinematic bicycle. Here the
vehicle is the centre-referenced unicycle of the paper's eq. (1),
s_{t+dt} = s_t + [v cos(theta), v sin(theta), omega] dt with |omega| <= |v| / R_min, and a maneuver is
built in three steps (all deterministic):

1. **Geometric plan.** Reeds-Shepp paths (:mod:`avp_world.reeds_shepp`; per leg the word minimising
   length + 3 m per cusp) with a planning radius 1.1 R_min (the 10 % curvature reserve is what the
   tracker uses to correct errors) are chained start -> pre-goal, either directly or through one
   intermediate "via" pose of a grid over the aisle (x in [-8, 8] every 1 m plus x = +-1.1 R_min, from
   where one quarter turn ends on the spot axis; y every 0.5 m plus both lane centres; heading every
   30 deg), or, as a fallback, through two vias. The pre-goal lies on the spot axis 1.0 or 0.5 m short of
   the spot centre and the plan ends with that straight into the spot, forward for head-in and in
   reverse for tail-in. Candidates are ranked by length + 3 m per cusp; the first one whose footprints,
   sampled every 5 cm, keep clearance + 0.05 m from every parked car and from the geofence wins.
2. **Time parameterisation.** The path is split at its cusps into pieces of one driving direction.
   On each piece the speed is the largest that |v| <= max_speed and |dv/dt| <= max_accel allow while
   still stopping exactly at the piece's end in whole steps of dt; one control with v = 0 is issued at
   every cusp and at the end. Defaults 2 m/s, 2 m/s^2 (ParkSim's parking limits); the §VI-A scenario
   generator uses 1.1 m/s, which gives ParkSim's pace: its H-OBCA horizon N is the number of Hybrid A*
   warm-start samples (0.1 m apart) at dt = 0.1 s, so a maneuver of L metres lasts about L seconds.
3. **Tracking.** The controls are produced while simulating eq. (1) itself (``step_vehicle``). An Euler
   step moves the car along its current heading, so the steering works one step ahead: omega_k sets
   theta_{k+1} to the reference heading at the middle of the next step (the chord direction of the
   reference arc, which cancels the drift of Euler steps off curves) minus d atan(e_lat / 1 m), e_lat
   being the lateral error of the already-determined position p_{k+1} and d = +-1 the driving
   direction; omega is clipped to |v| / R_min. The states of a :class:`Maneuver` are exactly
   ``rollout_vehicle(start, controls, dt)``, which is how the simulator replays them (they stay within
   about 1 cm of the plan). They are checked again: >= clearance - 0.05 m from the parked cars, inside
   the geofence, control bounds, final pose within 0.15 m laterally / 0.3 m longitudinally / 3 deg of
   the spot centre; otherwise the next plan is tried.

:func:`maneuver_to_world` moves a canonical maneuver onto a real spot; controls are frame-invariant.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from avp_scenario.maneuver_scene import (
    ALL_MANEUVERS,
    START_OFFSET,
    Maneuver,
    ManeuverKey,
    SceneGeometry,
    check_key,
    goal_pose,
    parked_car_poses,
    start_pose,
    target_spot_pose,
)
from avp_scenario.maneuver_tracking import MAX_ACCEL, MAX_SPEED, controls_ok, end_ok, pieces, track
from avp_world.geometry import rect_corners, rects_overlap, wrap_angle
from avp_world.kinematics import rollout_vehicle
from avp_world.reeds_shepp import RSBatch, RSPath, reeds_shepp_batch, sample_path
from avp_world.vehicle import VehicleSpec

__all__ = [
    "ALL_MANEUVERS",
    "MAX_ACCEL",
    "MAX_SPEED",
    "START_OFFSET",
    "Maneuver",
    "ManeuverKey",
    "SceneGeometry",
    "generate_maneuver",
    "goal_pose",
    "maneuver_to_world",
    "parked_car_poses",
    "start_pose",
    "target_spot_pose",
]


# planner / tracker tuning
_PLAN_RADIUS_FACTOR = 1.1  # plan with 1.1 R_min so the tracker keeps 10 % curvature authority
_PLAN_MARGIN = 0.05  # extra clearance (m) the plan keeps on top of SceneGeometry.clearance
_CUSP_PENALTY = 3.0  # m of path length per change of direction
_STRAIGHT_IN = (1.0, 0.5)  # m: every plan ends with a straight this long into the spot (tracking settles)
_PLAN_STEP = 0.05  # m between collision-checked samples of a plan
_VERIFY_SLACK = 0.05  # rolled-out footprints may use this much of the clearance


# -------------------------------------------------------------------------------- collision checking


class _Checker:
    """Footprint checks against the (margin-grown) parked cars and the (margin-shrunk) geofence."""

    def __init__(self, side: str, scene: SceneGeometry, vehicle: VehicleSpec, margin: float):
        self.vehicle = vehicle
        self.margin = margin
        self.cars = rect_corners(parked_car_poses(side, scene, vehicle), vehicle.length, vehicle.width)
        xmin, ymin, xmax, ymax = scene.geofence
        self.box = (xmin + margin, ymin + margin, xmax - margin, ymax - margin)
        # bounding-circle prefilter: only cars within reach of a footprint are tested with SAT
        self.car_centres = self.cars.mean(axis=1)
        self.reach = math.hypot(vehicle.length, vehicle.width) + margin + 1e-6

    def free(self, poses: np.ndarray) -> bool:
        """Whether every footprint keeps > margin from all parked cars and stays inside the geofence."""
        poses = np.asarray(poses, dtype=float).reshape(-1, 3)
        corners = rect_corners(poses, self.vehicle.length, self.vehicle.width)
        xmin, ymin, xmax, ymax = self.box
        cx, cy = corners[..., 0], corners[..., 1]
        if cx.min() < xmin or cx.max() > xmax or cy.min() < ymin or cy.max() > ymax:
            return False
        d = np.linalg.norm(poses[:, None, :2] - self.car_centres[None], axis=-1)
        ii, jj = np.nonzero(d < self.reach)
        if ii.size == 0:
            return True
        return not rects_overlap(corners[ii], self.cars[jj], margin=self.margin).any()


# ----------------------------------------------------------------------------------------- planning


@dataclass(frozen=True)
class _Plan:
    segments: tuple[tuple[str, float], ...]  # merged RS segments, signed metres
    cost: float


def _batch_segments(batch: RSBatch, i: int) -> list[tuple[str, float]]:
    return list(batch.path(int(i)).segments)


def _dir_stats(seg_lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per row of signed lengths (N, 5): number of cusps, first and last driving direction (0 = empty)."""
    s = np.where(np.abs(seg_lengths) > 1e-9, np.sign(seg_lengths), 0.0)
    n = s.shape[0]
    cusps = np.zeros(n, dtype=int)
    last = np.zeros(n)
    first = np.zeros(n)
    for j in range(s.shape[1]):
        sj = s[:, j]
        nz = sj != 0
        cusps += (nz & (last != 0) & (sj != last)).astype(int)
        first = np.where((first == 0) & nz, sj, first)
        last = np.where(nz, sj, last)
    return cusps, first, last


def _via_grid(scene: SceneGeometry, radius: float) -> np.ndarray:
    """Via poses over the aisle. Besides a regular grid, the abscissae x = +-radius are included (a quarter
    turn of the planning radius from there ends exactly on the spot axis x = 0, the only way to
    swing into the spot without a cusp when there is no room to spare) and the two lane centre lines."""
    half = scene.aisle_width / 2.0
    xs = np.union1d(np.arange(-8.0, 8.0 + 1e-9, 1.0), [-radius, radius])
    ys = np.union1d(np.arange(-half + 0.5, half - 0.5 + 1e-9, 0.5), [scene.lane_y, -scene.lane_y])
    ths = np.radians(np.arange(-180.0, 180.0, 30.0))
    g = np.stack(np.meshgrid(xs, ys, ths, indexing="ij"), axis=-1).reshape(-1, 3)
    return g


class _Planner:
    """Chains of Reeds-Shepp legs start -> [via [-> via]] -> pre-goal, then a straight into the spot."""

    def __init__(self, key: ManeuverKey, scene: SceneGeometry, vehicle: VehicleSpec):
        self.key = key
        self.radius = vehicle.min_turning_radius * _PLAN_RADIUS_FACTOR
        self.start = start_pose(key, scene)
        self.goal = goal_pose(key, scene)
        self.want_last = 1 if key.entry == "head_in" else -1
        # The legs end at a pre-goal on the spot axis, from which the last piece drives straight
        # (forward for head-in, reversing for tail-in) into the spot; a few lengths are tried.
        self.tails = [[("S", self.want_last * ln)] for ln in _STRAIGHT_IN]
        self.pre_goals = np.array(
            [self.goal - self.want_last * ln * np.array([math.cos(self.goal[2]), math.sin(self.goal[2]), 0.0])
             for ln in _STRAIGHT_IN]
        )
        self.checker = _Checker(key.side, scene, vehicle, scene.clearance + _PLAN_MARGIN)
        self.vias = _via_grid(scene, self.radius)
        self._leg_cache: dict[tuple, bool] = {}

    def _leg_free(self, a: np.ndarray, segs: list[tuple[str, float]]) -> bool:
        k = (tuple(np.round(a, 9)), tuple(segs))
        if k not in self._leg_cache:
            path = RSPath(segments=tuple(segs), length=sum(abs(s) for _, s in segs))
            poses, _ = sample_path(a, path, self.radius, _PLAN_STEP)
            self._leg_cache[k] = self.checker.free(poses)
        return self._leg_cache[k]

    def _final_legs(self, froms: np.ndarray):
        """RS legs from each of ``froms`` (N, 3) to each pre-goal, flattened (N * E): batch, from index,
        end index, cost (length + straight + cusps, inf where the leg does not end in the entry
        direction), first direction."""
        n, e = len(froms), len(self.pre_goals)
        b = reeds_shepp_batch(
            np.repeat(froms, e, axis=0), np.tile(self.pre_goals, (n, 1)), self.radius, _CUSP_PENALTY
        )
        c, f, last = _dir_stats(b.seg_lengths)
        ends = np.tile(np.arange(e), n)
        cost = b.length + np.asarray(_STRAIGHT_IN)[ends] + _CUSP_PENALTY * c
        cost = np.where((last == self.want_last) | (last == 0), cost, np.inf)
        return b, np.repeat(np.arange(n), e), ends, cost, f

    def plans(self, max_checked: int = 4000):
        """Yield collision-free plans (by increasing cost within each stage: direct, one via, two vias)."""
        r = self.radius
        bd, _, ends, cost, _ = self._final_legs(self.start[None])
        for k in np.argsort(cost, kind="stable"):
            segs = _batch_segments(bd, k) + self.tails[ends[k]]
            if np.isfinite(cost[k]) and self._leg_free(self.start, segs):
                yield _Plan(tuple(segs), float(cost[k]))

        vias = self.vias
        b1 = reeds_shepp_batch(self.start, vias, r, _CUSP_PENALTY)
        c1, _, l1 = _dir_stats(b1.seg_lengths)
        cost1 = b1.length + _CUSP_PENALTY * c1
        b2, from2, end2, cost2, f2 = self._final_legs(vias)
        join = (l1[from2] != 0) & (f2 != 0) & (l1[from2] != f2)
        cost = cost1[from2] + cost2 + _CUSP_PENALTY * join
        order = np.argsort(cost, kind="stable")
        for k in order[:max_checked]:
            if not np.isfinite(cost[k]):
                break
            i = from2[k]
            s1, s2 = _batch_segments(b1, i), _batch_segments(b2, k) + self.tails[end2[k]]
            if self._leg_free(self.start, s1) and self._leg_free(vias[i], s2):
                yield _Plan(tuple(s1 + s2), float(cost[k]))

        # two vias (slow fallback): the cheapest collision-free first legs, then the grid again
        firsts = []
        for i in np.argsort(cost1, kind="stable"):
            if self._leg_free(self.start, _batch_segments(b1, i)):
                firsts.append(i)
                if len(firsts) >= 12:
                    break
        cands = []
        for i in firsts:
            bm = reeds_shepp_batch(vias[i], vias, r, _CUSP_PENALTY)
            cm, fm, lm = _dir_stats(bm.seg_lengths)
            j1 = (l1[i] != 0) & (fm != 0) & (l1[i] != fm)
            mid = bm.length + _CUSP_PENALTY * (cm + j1)
            mid = np.where(bm.length > 1e-6, mid, np.inf)
            j2 = (lm[from2] != 0) & (f2 != 0) & (lm[from2] != f2)
            cc = cost1[i] + mid[from2] + cost2 + _CUSP_PENALTY * j2
            for k in np.argsort(cc, kind="stable")[:200]:
                if np.isfinite(cc[k]):
                    cands.append((float(cc[k]), int(i), int(k), _batch_segments(bm, from2[k])))
        cands.sort(key=lambda c: c[0])
        for c, i, k, sm in cands[:max_checked]:
            s1, s2 = _batch_segments(b1, i), _batch_segments(b2, k) + self.tails[end2[k]]
            if self._leg_free(vias[i], sm) and self._leg_free(vias[from2[k]], s2):
                yield _Plan(tuple(s1 + sm + s2), c)


# --------------------------------------------------------------------------------------------- API


@functools.lru_cache(maxsize=64)
def generate_maneuver(
    key: ManeuverKey,
    scene: SceneGeometry = SceneGeometry(),
    vehicle: VehicleSpec = VehicleSpec(),
    dt: float = 0.1,
    max_speed: float = MAX_SPEED,
    max_accel: float = MAX_ACCEL,
) -> Maneuver:
    """Plan, time-parameterise and track one of the 8 maneuvers (see the module docstring). Cached.

    ``max_speed`` / ``max_accel`` bound |v| and |dv/dt| of the time parameterisation (defaults: ParkSim's
    parking limits 2 m/s, 2 m/s^2); the geometric path does not depend on them.

    Raises:
        RuntimeError: no feasible maneuver was found for this scene/vehicle.
        ValueError: a non-positive ``max_speed`` or ``max_accel``.
    """
    key = check_key(key)
    if not (max_speed > 0 and max_accel > 0):
        raise ValueError(f"max_speed and max_accel must be > 0, got {max_speed}, {max_accel}")
    planner = _Planner(key, scene, vehicle)
    verify = _Checker(key.side, scene, vehicle, max(scene.clearance - _VERIFY_SLACK, 0.0))
    start = planner.start
    for n_tried, plan in enumerate(planner.plans()):
        if n_tried >= 50:
            break
        controls = track(start, pieces(start, plan.segments, planner.radius), vehicle, dt, max_speed, max_accel)
        states = rollout_vehicle(start, controls, dt)
        ok = controls_ok(controls, vehicle, dt, max_speed, max_accel) and end_ok(states[-1], planner.goal)
        if ok and verify.free(states):
            for a in (controls, states):
                a.flags.writeable = False
            s0 = start.copy()
            s0.flags.writeable = False
            return Maneuver(key=key, start=s0, controls=controls, states=states, dt=dt, scene=scene)
    raise RuntimeError(f"no feasible parking maneuver for {key} in {scene}")


def maneuver_to_world(
    maneuver: Maneuver, spot_pose: np.ndarray, aisle_width: float, side: str
) -> tuple[np.ndarray, np.ndarray]:
    """Rigidly move a canonical maneuver so that its target spot lands on a real spot.

    The canonical target spot has centre (0, -/+(aisle/2 + spot_length/2)) and heading psi_c = -pi/2
    (near) or +pi/2 (far). The transform is the rotation by alpha = psi_w - psi_c followed by the
    translation taking the canonical spot centre onto the world one:

        p_w = R(alpha) (p_c - c_spot) + p_spot,    theta_w = theta_c + alpha.

    So the car's canonical heading 0 (driving east along the aisle) becomes alpha = psi_w + pi/2 for a
    near-side spot (the spot lies on the car's right: its heading is the travel heading - pi/2) and
    psi_w - pi/2 for a far-side one (spot on the left). Because the map is rigid, eq. (1) commutes
    with it and the same controls replay the world states.

    Args:
        spot_pose: (3,) world centre and heading (pointing away from the aisle) of the real spot.
        aisle_width: the world aisle width; must equal the one the maneuver was generated for
            (``maneuver.scene.aisle_width``, within 1 cm), else the start would not be in the lane.
        side: 'near' or 'far' (must match ``maneuver.key.side``).

    Returns:
        (start_world (3,), states_world (T + 1, 3)); headings wrapped to [-pi, pi). Controls are unchanged.
    """
    if side != maneuver.key.side:
        raise ValueError(f"side {side!r} does not match the maneuver's side {maneuver.key.side!r}")
    if abs(aisle_width - maneuver.scene.aisle_width) > 0.01:
        raise ValueError(
            f"aisle width {aisle_width} m differs from the maneuver's {maneuver.scene.aisle_width} m; "
            "generate it with SceneGeometry(aisle_width=...)"
        )
    spot_pose = np.asarray(spot_pose, dtype=float)
    canon = target_spot_pose(side, maneuver.scene)
    alpha = spot_pose[2] - canon[2]
    c, s = math.cos(alpha), math.sin(alpha)
    rot = np.array([[c, -s], [s, c]])

    def tf(p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, dtype=float)
        out = np.empty_like(p)
        out[..., :2] = (p[..., :2] - canon[:2]) @ rot.T + spot_pose[:2]
        out[..., 2] = wrap_angle(p[..., 2] + alpha)
        return out

    return tf(maneuver.start), tf(maneuver.states)

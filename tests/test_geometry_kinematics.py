"""Rectangle geometry against shapely; eq. (1) and eq. (2) against hand computation."""

from __future__ import annotations

import math

import numpy as np
from shapely import affinity
from shapely.geometry import Point, Polygon, box

from avp_world.geometry import disc_rect_overlap, rect_corners, rect_inside_rect, rects_overlap
from avp_world.kinematics import rollout_vehicle, step_pedestrian, step_vehicle


def _shapely_rect(pose, length, width):
    r = box(-length / 2, -width / 2, length / 2, width / 2)
    r = affinity.rotate(r, pose[2], origin=(0, 0), use_radians=True)
    return affinity.translate(r, pose[0], pose[1])


def test_rect_corners_match_shapely():
    rng = np.random.default_rng(0)
    for _ in range(200):
        pose = rng.uniform([-10, -10, -4], [10, 10, 4])
        length, width = rng.uniform(0.5, 6, 2)
        ours = Polygon(rect_corners(pose, length, width))
        ref = _shapely_rect(pose, length, width)
        assert ours.symmetric_difference(ref).area < 1e-9


def test_overlap_inside_disc_vs_shapely():
    rng = np.random.default_rng(1)
    n_overlap = 0
    for _ in range(2000):
        a = rng.uniform([-4, -4, -4], [4, 4, 4])
        b = rng.uniform([-4, -4, -4], [4, 4, 4])
        la, wa, lb, wb = rng.uniform(0.5, 5, 4)
        pa, pb = _shapely_rect(a, la, wa), _shapely_rect(b, lb, wb)
        ca, cb = rect_corners(a, la, wa), rect_corners(b, lb, wb)
        d = pa.distance(pb)
        inter = pa.intersection(pb).area
        if d > 1e-7 or inter > 1e-7:  # skip numerically touching cases
            assert bool(rects_overlap(ca, cb)) == (inter > 0), (a, b)
            n_overlap += inter > 0
        if pa.difference(pb).area > 1e-7 or pa.within(pb):
            assert bool(rect_inside_rect(ca, cb)) == pa.within(pb.buffer(1e-9))
        c, r = rng.uniform(-5, 5, 2), rng.uniform(0.1, 1.5)
        dist = pb.distance(Point(*c))
        if abs(dist - r) > 1e-7:
            assert bool(disc_rect_overlap(c, r, cb)) == (dist <= r)
    assert 200 < n_overlap < 1800  # both outcomes exercised


def test_overlap_margin():
    a = rect_corners(np.array([0.0, 0.0, 0.0]), 2.0, 2.0)
    b = rect_corners(np.array([2.5, 0.0, 0.0]), 2.0, 2.0)  # 0.5 m gap
    assert not rects_overlap(a, b)
    assert rects_overlap(a, b, margin=0.6)
    assert not rects_overlap(a, b, margin=0.4)


def test_eq1_step_by_hand():
    s = np.array([1.0, 2.0, math.pi / 2])
    out = step_vehicle(s, np.array([2.0, 0.5]), 0.1)
    assert np.allclose(out, [1.0 + 2.0 * math.cos(math.pi / 2) * 0.1, 2.0 + 2.0 * 0.1, math.pi / 2 + 0.05])
    # heading wraps into [-pi, pi)
    out = step_vehicle(np.array([0.0, 0.0, math.pi - 0.01]), np.array([0.0, 1.0]), 0.1)
    assert -math.pi <= out[2] < math.pi and math.isclose(out[2], -math.pi + 0.09, abs_tol=1e-12)


def test_rollout_circle_and_batch():
    # constant (v, omega) traces a polygon inscribed in a circle of radius v / omega (Euler of eq. 1)
    v, om, dt = 1.0, 0.5, 0.1
    traj = rollout_vehicle(np.zeros(3), np.tile([v, om], (126, 1)), dt)
    assert traj.shape == (127, 3)
    r = v / om
    centre = np.array([0.0, r])
    d = np.linalg.norm(traj[:, :2] - centre, axis=1)
    assert np.all(np.abs(d - d[0]) < 0.15)  # stays near the circle
    batch = rollout_vehicle(np.zeros((5, 3)), np.tile([v, om], (10, 5, 1)), dt)
    assert batch.shape == (11, 5, 3) and np.allclose(batch[:, 0], traj[:11])


def test_eq2_pedestrian():
    p = step_pedestrian(np.array([[0.0, 0.0]]), np.array([[1.5, math.pi / 2]]), 0.2)
    assert np.allclose(p, [[0.0, 0.3]])


def test_brake_speed_is_the_smallest_whole_step_trapezoid():
    """avp_world.kinematics.brake_speed (one function for the planner, the agents' maneuvers and the training
    traffic) against its definition walked from n = 0, and against a rollout: braking by dv each step
    from the returned speed stops within rem."""
    import math
    import random

    from avp_world.kinematics import brake_speed

    def by_definition(rem, dt, dv):
        if rem <= 0:
            return 0.0
        for n in range(100000):
            v = rem / (dt * (n + 1)) + dv * n / 2.0
            if v < (n + 1) * dv:
                return max(v, n * dv)
        return math.inf

    rng = random.Random(7)
    for _ in range(20000):
        rem, dt, dv = rng.uniform(-1.0, 60.0), rng.choice([0.05, 0.1, 0.5]), rng.uniform(0.01, 0.5)
        assert brake_speed(rem, dt, dv) == by_definition(rem, dt, dv)
    v, rem, dt, dv = brake_speed(10.0, 0.1, 0.15), 10.0, 0.1, 0.15
    travelled = 0.0
    while v > 1e-12:
        travelled += v * dt
        v = max(v - dv, 0.0)
    assert travelled <= rem + 1e-9
    assert brake_speed(5.0, 0.1, 0.0) == math.inf and brake_speed(0.0, 0.1, 0.1) == 0.0

"""Trajectory prediction of §V-C (``avp_predictors.prediction``).

Oracles: control points worked out by hand from eqs. (9)-(12); the curve length by dense numerical
integration of |B'(u)| written here; geometry of the predicted poses (spacing, end point, tangents).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from avp_predictors.intention import Intention
from avp_predictors.prediction import (
    BezierPredictor,
    ConstantVelocityPredictor,
    PredictionConfig,
    bezier_control_points,
    follow_bezier,
    make_predictor,
    vehicle_motion,
)
from avp_world.lot import load_bundled_lot
from avp_world.types import Observation, ObservedPedestrian, ObservedVehicle

LOT = load_bundled_lot("paper_lot")
DT = 0.1


def vehicle(vid, pose, speed, reverse=False, n=41, static=False) -> ObservedVehicle:
    """Straight history at ``speed`` along the heading (backwards if ``reverse``)."""
    p = np.asarray(pose, dtype=float)
    sgn = -1.0 if reverse else 1.0
    back = sgn * speed * DT * np.arange(n - 1, -1, -1)
    hist = np.column_stack([p[0] - back * math.cos(p[2]), p[1] - back * math.sin(p[2]), np.full(n, p[2])])
    return ObservedVehicle(id=vid, length=4.6, width=1.85, is_static=static, history=hist)


def obs_with(vehicles=(), pedestrians=()) -> Observation:
    return Observation(step=0, dt=DT, ego_pose=np.array([21.5, 38.0, -math.pi / 2]), ego_length=4.6,
                       ego_width=1.85, ego_speed=0.0, vacant_spot_ids=np.zeros(0, np.int64),
                       occupied_spot_ids=np.zeros(0, np.int64), vehicles=tuple(vehicles),
                       pedestrians=tuple(pedestrians))


def curve_length(ctrl, n=200_001):
    """Oracle: trapezoidal integral of |B'(u)| with the derivative written out here."""
    u = np.linspace(0.0, 1.0, n)[:, None]
    p0, p1, p2, p3 = ctrl
    d = 3 * (1 - u) ** 2 * (p1 - p0) + 6 * (1 - u) * u * (p2 - p1) + 3 * u**2 * (p3 - p2)
    s = np.hypot(d[:, 0], d[:, 1])
    return float(np.sum(0.5 * (s[1:] + s[:-1])) / (n - 1))


def test_control_points_by_hand():
    pose = np.array([0.0, 0.0, 0.0])
    goal = np.array([10.0, 5.0, math.pi / 2])
    # eq. (11) as printed: P1 = p + zeta v [cos(theta + pi), sin(theta + pi)] = (-6, 0)
    np.testing.assert_allclose(bezier_control_points(pose, 2.0, goal, 3.0),
                               [[0, 0], [-6, 0], [10, -1], [10, 5]], atol=1e-12)
    # forward start direction: P1 = (6, 0); P2 = goal + 6 [cos(3pi/2), sin(3pi/2)] = (10, -1)
    np.testing.assert_allclose(bezier_control_points(pose, 2.0, goal, 3.0, start_angle=0.0),
                               [[0, 0], [6, 0], [10, -1], [10, 5]], atol=1e-12)


def test_speed_and_direction_from_history():
    assert vehicle_motion(vehicle(1, (0, 0, 0.3), 1.5).history, DT) == (pytest.approx(1.5), False)
    assert vehicle_motion(vehicle(1, (0, 0, 0.3), 1.5, reverse=True).history, DT) == (pytest.approx(1.5), True)
    assert vehicle_motion(vehicle(1, (0, 0, 0.3), 0.0).history, DT) == (0.0, False)


def spot_pose(sid):
    return LOT.spot_poses[LOT.spot_index(sid)]


@pytest.mark.parametrize("speed", [1.0, 2.0])
def test_bezier_to_a_spot_start_end_tangents_and_constant_speed(speed):
    # vehicle driving north on the middle road, spot 13 (west of the road, heading pi: nose in = west)
    v = vehicle(1000, (21.5, 10.0, math.pi / 2), speed)
    goal = spot_pose(13)
    it = Intention(1000, np.array([13]), np.array([0.9]), none_probability=0.1)
    cfg = PredictionConfig(t_pred=30.0, horizon=30.0)
    trajs = BezierPredictor(LOT, cfg).predict(obs_with([v]), [it])
    assert len(trajs) == 1
    t = trajs[0]
    assert t.agent_id == 1000 and t.spot_id == 13 and t.probability == pytest.approx(0.9)
    assert t.poses.shape == (300, 3) and t.dt == DT
    ctrl = bezier_control_points(v.pose, speed, goal, 3.0, start_angle=math.pi / 2)
    length = curve_length(ctrl)
    pts = np.vstack([v.pose[:2], t.poses[:, :2]])
    steps = np.hypot(*np.diff(pts, axis=0).T)
    # constant speed: consecutive positions v dt apart (chords of a curve: a hair shorter than arcs)
    np.testing.assert_allclose(steps, speed * DT, atol=2e-3)
    # the curve is left where its length is used up; the goal lies on the path there
    j_end = int(math.floor(length / (speed * DT) + 1e-9))  # last step still on the curve (1-based)
    assert np.hypot(*(t.poses[j_end - 1, :2] - goal[:2])) <= speed * DT + 1e-6
    # after the curve: straight on from the goal along the spot heading (constant velocity)
    u_goal = np.array([math.cos(goal[2]), math.sin(goal[2])])
    for j in (j_end, j_end + 5, 299):
        s_after = (j + 1) * speed * DT - length
        np.testing.assert_allclose(t.poses[j, :2], goal[:2] + s_after * u_goal, atol=2e-3)
        assert math.cos(t.poses[j, 2] - goal[2]) == pytest.approx(1.0, abs=1e-6)
    # start: first step leaves along the heading (P1 - P0); end: arrives along theta_goal (P3 - P2)
    first = t.poses[0, :2] - v.pose[:2]
    assert math.atan2(first[1], first[0]) == pytest.approx(math.pi / 2, abs=0.02)
    assert math.cos(t.poses[0, 2] - math.pi / 2) == pytest.approx(1.0, abs=1e-3)
    last = t.poses[j_end - 1, :2] - t.poses[j_end - 2, :2]
    assert math.cos(math.atan2(last[1], last[0]) - goal[2]) == pytest.approx(1.0, abs=1e-3)


def test_bezier_curve_phase_ends_at_t_pred_then_constant_velocity():
    v = vehicle(1000, (21.5, 10.0, math.pi / 2), 2.0)
    it = Intention(1000, np.array([13]), np.array([1.0]))
    t = BezierPredictor(LOT, PredictionConfig(t_pred=1.0, horizon=3.0)).predict(obs_with([v]), [it])[0]
    assert t.poses.shape == (30, 3)
    full = BezierPredictor(LOT, PredictionConfig(t_pred=3.0, horizon=3.0)).predict(obs_with([v]), [it])[0]
    np.testing.assert_allclose(t.poses[:10], full.poses[:10], atol=1e-9)  # same curve up to t_pred
    d = 2.0 * DT * np.array([math.cos(t.poses[9, 2]), math.sin(t.poses[9, 2])])  # tangent at t_pred, v dt
    assert np.hypot(*(t.poses[9, :2] - t.poses[8, :2] - d)) < 2e-3
    for j in range(10, 30):  # then a straight line at the same speed and heading
        np.testing.assert_allclose(t.poses[j, :2], t.poses[9, :2] + (j - 9) * d, atol=1e-9)
        assert t.poses[j, 2] == pytest.approx(t.poses[9, 2])
    assert not np.allclose(t.poses[20:], full.poses[20:], atol=0.05)


def test_reversing_vehicle_motion_vs_paper_start_tangent():
    # backing north-west into spot 13 while facing east: motion direction = theta + pi (eq. 11 literally)
    v = vehicle(1000, (21.5, 12.0, 0.0), 1.0, reverse=True)
    it = Intention(1000, np.array([13]), np.array([1.0]))
    motion = BezierPredictor(LOT, PredictionConfig(start_tangent="motion")).predict(obs_with([v]), [it])[0]
    paper = BezierPredictor(LOT, PredictionConfig(start_tangent="paper")).predict(obs_with([v]), [it])[0]
    np.testing.assert_allclose(motion.poses[:, :2], paper.poses[:, :2])
    first = motion.poses[0, :2] - v.pose[:2]
    assert first[0] < 0 and abs(first[1]) < 0.02  # leaves westwards (backwards)
    assert math.cos(motion.poses[0, 2] - 0.0) == pytest.approx(1.0, abs=1e-3)  # still facing east
    # a forward-driving car: "paper" starts backwards, "motion"/"heading" forwards
    f = vehicle(1000, (21.5, 10.0, math.pi / 2), 1.0)
    back = BezierPredictor(LOT, PredictionConfig(start_tangent="paper")).predict(obs_with([f]), [it])[0]
    fwd = BezierPredictor(LOT, PredictionConfig(start_tangent="heading")).predict(obs_with([f]), [it])[0]
    assert back.poses[0, 1] < 10.0 < fwd.poses[0, 1]


def test_mu_threshold_exploration_and_fallbacks():
    v = vehicle(1000, (21.5, 10.0, math.pi / 2), 1.5)
    explore = np.array([[21.5, 21.5, math.pi / 2], [10.0, 3.5, math.pi]])
    it = Intention(1000, np.array([12, 13, 22]), np.array([0.31, 0.29, 0.05]), explore, np.array([0.3, 0.05]),
                   none_probability=0.35)
    trajs = BezierPredictor(LOT).predict(obs_with([v]), [it])
    assert sorted((t.spot_id, round(t.probability, 2)) for t in trajs) == [(-1, 0.3), (12, 0.31)]
    ex = next(t for t in trajs if t.spot_id == -1)
    # exploration goal on the road straight ahead: the path stays on x = 21.5
    np.testing.assert_allclose(ex.poses[:, 0], 21.5, atol=1e-9)
    # "none" mass >= mu without exploration points: constant velocity with that probability
    it2 = Intention(1000, np.array([12]), np.array([0.4]), none_probability=0.6)
    t2 = BezierPredictor(LOT).predict(obs_with([v]), [it2])
    assert sorted(round(t.probability, 2) for t in t2) == [0.4, 0.6]
    # nothing >= mu, or no intention at all: one constant-velocity prediction with probability 1
    it3 = Intention(1000, np.array([12, 13, 14]), np.array([0.25, 0.25, 0.25]), none_probability=0.25)
    for trajs in (BezierPredictor(LOT).predict(obs_with([v]), [it3]), BezierPredictor(LOT).predict(obs_with([v]))):
        assert len(trajs) == 1 and trajs[0].probability == 1.0
        np.testing.assert_allclose(trajs[0].poses[:, 1], 10.0 + 0.15 * np.arange(1, 41), atol=1e-9)


def test_stationary_vehicle_stays_put():
    v = vehicle(1000, (21.5, 10.0, math.pi / 2), 0.0)
    t = BezierPredictor(LOT).predict(obs_with([v]), [Intention(1000, np.array([13]), np.array([1.0]))])[0]
    np.testing.assert_allclose(t.poses, np.tile(v.pose, (40, 1)))


def test_constant_velocity_on_a_straight_history():
    v = vehicle(7, (5.0, 3.5, 0.25), 2.0)
    ped = ObservedPedestrian(id=3, radius=0.3, position=np.array([10.0, 10.0]),
                             previous_position=np.array([10.1, 9.9]))
    parked = vehicle(8, tuple(spot_pose(3)), 0.0, static=True)
    trajs = ConstantVelocityPredictor(LOT).predict(obs_with([v, parked], [ped]), horizon=2.0)
    assert [t.agent_id for t in trajs] == [7, 3]  # static vehicles are not predicted
    tv, tp = trajs
    j = np.arange(1, 21)
    np.testing.assert_allclose(tv.poses[:, 0], 5.0 + 0.2 * j * math.cos(0.25), atol=1e-9)
    np.testing.assert_allclose(tv.poses[:, 1], 3.5 + 0.2 * j * math.sin(0.25), atol=1e-9)
    np.testing.assert_allclose(tv.poses[:, 2], 0.25)
    assert not tv.is_pedestrian and tv.length == 4.6 and tv.probability == 1.0
    np.testing.assert_allclose(tp.poses[:, :2], np.column_stack([10.0 - 0.1 * j, 10.0 + 0.1 * j]), atol=1e-12)
    np.testing.assert_array_equal(tp.poses[:, 2], 0.0)
    assert tp.is_pedestrian and tp.radius == 0.3
    # the Bezier predictor treats pedestrians the same way (no pedestrian intentions, §V-C)
    tb = BezierPredictor(LOT).predict(obs_with([], [ped]), horizon=2.0)
    np.testing.assert_allclose(tb[0].poses, tp.poses)


def test_predictor_registry_and_validation():
    assert isinstance(make_predictor("bezier", LOT), BezierPredictor)
    assert isinstance(make_predictor("constant_velocity"), ConstantVelocityPredictor)
    with pytest.raises(ValueError, match="bezier"):
        make_predictor("transformer", LOT)
    with pytest.raises(ValueError, match="start_tangent"):
        PredictionConfig(start_tangent="sideways").validate()
    with pytest.raises(ValueError, match="mu"):
        PredictionConfig(mu=1.5).validate()
    assert follow_bezier(np.zeros((4, 2)), 1.0, DT, 0, 0, 0.0).shape == (0, 3)

"""The Hybrid A* predictor (``avp_predictors.prediction_astar``).

Oracles independent of the code under test: shapely polygons for collisions with the spots / static cars
and for staying in the lot; the spot's own pose and rectangle for "ends in the intended spot"; arc length
summed from the poses for the constant speed; the turning-radius bound of the vehicle for curvature;
constant velocity written out here for the fallbacks.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import Polygon

from avp_predictors.intention import Intention
from avp_predictors.prediction import PredictionConfig, make_predictor
from avp_predictors.prediction_astar import HybridAStarPredictor, follow_path
from avp_search.paths import Path
from avp_world.geometry import rect_corners
from avp_world.lot import load_bundled_lot
from avp_world.types import Observation, ObservedPedestrian, ObservedVehicle
from avp_world.vehicle import VehicleSpec

LOT = load_bundled_lot("paper_lot")
DT = 0.1
L, W = 4.6, 1.85
R_MIN = VehicleSpec().min_turning_radius


def vehicle(vid, pose, speed, n=41, static=False) -> ObservedVehicle:
    """Straight history at ``speed`` along the heading, ending at ``pose``."""
    p = np.asarray(pose, dtype=float)
    back = speed * DT * np.arange(n - 1, -1, -1)
    hist = np.column_stack([p[0] - back * math.cos(p[2]), p[1] - back * math.sin(p[2]), np.full(n, p[2])])
    return ObservedVehicle(id=vid, length=L, width=W, is_static=static, history=hist)


def parked(vid, spot_id) -> ObservedVehicle:
    x, y, th = LOT.spot_poses[LOT.spot_index(spot_id)]
    return vehicle(vid, (x, y, th), 0.0, n=2, static=True)


def obs_with(vehicles=(), pedestrians=()) -> Observation:
    return Observation(step=0, dt=DT, ego_pose=np.array([21.5, 38.0, -math.pi / 2]), ego_length=L, ego_width=W,
                       ego_speed=0.0, vacant_spot_ids=np.zeros(0, np.int64), occupied_spot_ids=np.zeros(0, np.int64),
                       vehicles=tuple(vehicles), pedestrians=tuple(pedestrians))


def footprint(pose, length=L, width=W) -> Polygon:
    return Polygon(rect_corners(np.asarray(pose, dtype=float), length, width))


def spot_polygon(spot_id) -> Polygon:
    return Polygon(LOT.spot_corners[LOT.spot_index(spot_id)])


# a car driving south on the middle road (x = 21.5) at 2 m/s, between spot columns 10-19 (west) and 20-29 (east)
CAR = vehicle(1000, (21.5, 30.0, -math.pi / 2), 2.0)
LONG = PredictionConfig(t_pred=15.0)  # long enough to reach the spots


def intention(spots, probs, none=None, points=None, point_probs=None) -> Intention:
    p = np.asarray(probs, dtype=float)
    pts = np.zeros((0, 3)) if points is None else np.asarray(points, dtype=float)
    pp = np.zeros(0) if point_probs is None else np.asarray(point_probs, dtype=float)
    return Intention(1000, np.asarray(spots, dtype=np.int64), p, pts, pp,
                     float(1.0 - p.sum()) if none is None else none)


@pytest.fixture(scope="module")
def predictor():
    return HybridAStarPredictor(LOT, LONG)


def test_registered_and_listed():
    assert isinstance(make_predictor("hybrid_astar", LOT), HybridAStarPredictor)
    with pytest.raises(ValueError, match="hybrid_astar"):
        make_predictor("nope", LOT)


def test_one_trajectory_per_intention_above_mu_with_its_probability(predictor):
    it = intention([24, 14, 25], [0.55, 0.35, 0.05])  # none = 0.05, no exploration point
    trajs = predictor.predict(obs_with([CAR]), [it])
    assert [t.spot_id for t in trajs] == [24, 14]  # 0.05 < mu: no trajectory for spot 25, none below mu too
    assert [t.probability for t in trajs] == [0.55, 0.35]
    for t in trajs:
        assert t.agent_id == 1000 and t.dt == DT and not t.is_pedestrian
        np.testing.assert_array_equal(t.goal, LOT.spot_poses[LOT.spot_index(t.spot_id)])
        assert t.poses.shape == (int(round(LONG.t_pred / DT)), 3)
    assert predictor.last_stats["paths"] == 2


@pytest.mark.parametrize("spot_id", [24, 14, 27, 21])
def test_path_is_collision_free_and_ends_parked_in_the_intended_spot(predictor, spot_id):
    statics = [parked(2000 + k, s) for k, s in enumerate((23, 25, 13, 15))]  # neighbours of the spots taken
    obs = obs_with([CAR, *statics])
    trajs = predictor.predict(obs, [intention([spot_id], [1.0], none=0.0)])
    assert len(trajs) == 1
    t = trajs[0]
    poses = t.poses
    # 1. in the lot, clear of every spot but the goal (shapely); clear of the parked cars
    lot_poly = Polygon(LOT.boundary)
    others = [spot_polygon(s) for s in LOT.spot_ids if s != spot_id]
    cars = [footprint(v.pose) for v in statics]
    start = footprint(CAR.pose)
    for q in poses:
        fp = footprint(q)
        assert lot_poly.contains(fp)
        assert not any(fp.intersects(o) for o in others if not o.intersects(start))
        assert not any(fp.intersects(c) for c in cars)
    # 2. ends in the intended spot: at its centre, aligned with it (either way round), inside its rectangle
    end = poses[-1]
    sx, sy, sth = LOT.spot_poses[LOT.spot_index(spot_id)]
    assert math.hypot(end[0] - sx, end[1] - sy) < 1e-6
    assert abs(math.sin(end[2] - sth)) < 1e-6
    assert spot_polygon(spot_id).buffer(1e-6).contains(footprint(end))
    assert np.allclose(poses[-5:], end)  # parked: it stays there
    # 3. constant speed 2 m/s along the path until parked (a chord is shorter only where the step holds a cusp),
    # turning no tighter than R_min
    all_poses = np.vstack([CAR.pose, poses])
    d = np.diff(all_poses[:, :2], axis=0)
    step = np.hypot(d[:, 0], d[:, 1])
    moving = step > 1e-9
    n_move = int(moving.sum())
    assert np.all(step[: n_move - 1] <= 2.0 * DT + 1e-9)
    sign = np.sign(np.einsum("ij,ij->i", d, np.column_stack([np.cos(all_poses[1:, 2]), np.sin(all_poses[1:, 2])])))
    for k in np.nonzero(step[: n_move - 1] < 0.9 * 2.0 * DT)[0]:
        assert 0 < k and sign[k - 1] != sign[k + 1], f"step {k} is short but holds no cusp"
    dth = np.abs((np.diff(np.concatenate([[CAR.pose[2]], poses[:, 2]])) + math.pi) % (2 * math.pi) - math.pi)
    assert np.all(dth[moving] <= 2.0 * DT / R_MIN + 1e-9)  # each step is at most v dt of arc


def test_exploration_point_goal_then_keeps_going_along_the_road(predictor):
    goal = np.array([21.5, 18.0, -math.pi / 2])  # 12 m ahead on the same road
    it = intention([], [], none=0.8, points=[goal], point_probs=[0.8])
    (t,) = predictor.predict(obs_with([CAR]), [it])
    assert t.spot_id == -1 and t.probability == 0.8
    np.testing.assert_array_equal(t.goal, goal)
    reach = int(round(12.0 / (2.0 * DT)))  # straight ahead: the point is reached after 60 steps
    assert np.allclose(t.poses[reach - 1], goal, atol=1e-6)
    after = t.poses[reach:]  # then straight on at 2 m/s along the road heading
    k = np.arange(1, len(after) + 1)
    np.testing.assert_allclose(after[:, 1], goal[1] - 2.0 * DT * k, atol=1e-6)
    np.testing.assert_allclose(after[:, 0], goal[0], atol=1e-6)


def cv_oracle(v: ObservedVehicle, n: int) -> np.ndarray:
    d = v.history[-1, :2] - v.history[-2, :2]
    j = np.arange(1, n + 1)[:, None]
    return np.column_stack([v.pose[0] + j[:, 0] * d[0], v.pose[1] + j[:, 0] * d[1], np.full(n, v.pose[2])])


def test_no_plan_falls_back_to_constant_velocity_with_the_intention(predictor):
    blocker = parked(2000, 24)  # the intended spot holds a parked car: goal in collision
    (t,) = predictor.predict(obs_with([CAR, blocker]), [intention([24], [0.7], none=0.3)])[:1]
    assert t.spot_id == 24 and t.probability == 0.7
    np.testing.assert_allclose(t.poses, cv_oracle(CAR, len(t.poses)), atol=1e-12)
    assert predictor.last_stats["failures"][0][2] == "goal in collision"


def test_iteration_cap_gives_constant_velocity():
    tiny = HybridAStarPredictor(LOT, PredictionConfig(t_pred=15.0).__class__(
        t_pred=15.0, hybrid_astar=LONG.hybrid_astar.__class__(max_iterations=1)))
    (t,) = tiny.predict(obs_with([CAR]), [intention([29], [1.0], none=0.0)])  # far spot: needs a search
    np.testing.assert_allclose(t.poses, cv_oracle(CAR, len(t.poses)), atol=1e-12)
    assert "iterations" in tiny.last_stats["failures"][0][2]


def test_stopped_vehicle_stays_put(predictor):
    car = vehicle(1000, (21.5, 30.0, -math.pi / 2), 0.0)
    (t,) = predictor.predict(obs_with([car]), [intention([24], [1.0], none=0.0)])
    np.testing.assert_array_equal(t.poses, np.tile(car.pose, (len(t.poses), 1)))
    assert t.spot_id == 24


def test_min_speed_moves_a_stopped_vehicle():
    car = vehicle(1000, (21.5, 30.0, -math.pi / 2), 0.0)
    cfg = PredictionConfig(t_pred=15.0, hybrid_astar=LONG.hybrid_astar.__class__(min_speed=1.5))
    (t,) = HybridAStarPredictor(LOT, cfg).predict(obs_with([car]), [intention([24], [1.0], none=0.0)])
    first = math.hypot(*(t.poses[0, :2] - car.pose[:2]))
    assert first == pytest.approx(1.5 * DT, rel=1e-3)


def test_unconditioned_vehicles_and_pedestrians_at_constant_velocity(predictor):
    ped = ObservedPedestrian(7, 0.3, np.array([20.0, 10.0]), np.array([20.0, 10.1]))
    trajs = predictor.predict(obs_with([CAR], [ped]), [])
    car_t = [t for t in trajs if not t.is_pedestrian]
    ped_t = [t for t in trajs if t.is_pedestrian]
    assert len(car_t) == 1 and car_t[0].probability == 1.0 and car_t[0].goal is None
    np.testing.assert_allclose(car_t[0].poses, cv_oracle(CAR, len(car_t[0].poses)), atol=1e-12)
    n = len(ped_t[0].poses)
    np.testing.assert_allclose(ped_t[0].poses[:, 1], 10.0 - 0.1 * np.arange(1, n + 1), atol=1e-12)
    # the "none" mass >= mu without an exploration point: constant velocity carrying that mass
    trajs = predictor.predict(obs_with([CAR]), [intention([24], [0.5], none=0.5)])
    assert sorted((t.spot_id, t.probability) for t in trajs) == [(-1, 0.5), (24, 0.5)]


def test_deterministic_and_world_reused():
    a, b = HybridAStarPredictor(LOT, LONG), HybridAStarPredictor(LOT, LONG)
    obs = obs_with([CAR, parked(2000, 23)])
    its = [intention([24, 14], [0.5, 0.4], none=0.1)]
    ta, tb = a.predict(obs, its), b.predict(obs, its)
    assert a.last_stats["worlds_built"] == 1
    for x, y in zip(ta, tb, strict=True):
        np.testing.assert_array_equal(x.poses, y.poses)
    a.predict(obs, its)  # same obstacle set: the cached static world is used
    assert "worlds_built" not in a.last_stats


def test_follow_path_constant_speed_then_straight_on():
    path = Path((0.0, 0.0, 0.0), ((0.0, 1.0), (0.0, -0.5)))  # 1 m forward, then 0.5 m in reverse
    poses = follow_path(path, 1.0, 0.1, 20, 12, hold_at_end=False)
    np.testing.assert_allclose(poses[:10, 0], 0.1 * np.arange(1, 11), atol=1e-12)  # forward leg
    np.testing.assert_allclose(poses[10:12, 0], [0.9, 0.8], atol=1e-12)  # reversing, heading kept
    np.testing.assert_allclose(poses[:, 2], 0.0, atol=1e-12)
    np.testing.assert_allclose(poses[12:, 0], 0.8 - 0.1 * np.arange(1, 9), atol=1e-12)  # after t_pred: CV
    held = follow_path(path, 1.0, 0.1, 20, 20, hold_at_end=True)
    np.testing.assert_allclose(held[14:, 0], 0.5, atol=1e-12)  # path over after 1.5 m: stays at its end


def test_cached_heuristic_gives_the_fresh_result():
    """A predictor that has seen the previous step (warm world and distance-map caches) predicts the next
    step exactly like a fresh one."""
    its = [intention([24, 14], [0.5, 0.4], none=0.1)]
    warm = HybridAStarPredictor(LOT, LONG)
    for y in (30.4, 30.2, 30.0):  # the car drives south 0.2 m per step, staying in one 1 m heuristic cell
        out = warm.predict(obs_with([vehicle(1000, (21.5, y, -math.pi / 2), 2.0)]), its)
    assert "worlds_built" not in warm.last_stats
    assert len({id(m) for m in warm._heuristics.values()}) == 1  # one map, found by its world or its coarse cells
    fresh = HybridAStarPredictor(LOT, LONG).predict(obs_with([CAR]), its)
    for a, b in zip(out, fresh, strict=True):
        np.testing.assert_array_equal(a.poses, b.poses)

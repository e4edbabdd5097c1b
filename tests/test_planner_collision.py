"""Static world and dynamic obstacles of the §V-D planner vs independent shapely oracles."""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely import affinity
from shapely.geometry import Point, Polygon, box
from shapely.ops import unary_union

from avp_collision.static import DynamicObstacles, StaticWorld, merge_rects, merge_rects_after
from avp_search.settings import CollisionSettings
from avp_world.types import PredictedTrajectory

L, W = 4.6, 1.85


def footprint(x: float, y: float, th: float, length: float = L, width: float = W) -> Polygon:
    """Oracle footprint: an axis-aligned box rotated and moved with shapely (independent of the planner)."""
    b = box(-length / 2, -width / 2, length / 2, width / 2)
    return affinity.translate(affinity.rotate(b, th, origin=(0, 0), use_radians=True), x, y)


def oracle_free(poly: Polygon, lot_poly: Polygon, obstacles, margin: float) -> bool:
    if not poly.within(lot_poly) or poly.distance(lot_poly.exterior) < margin:
        return False
    return obstacles.is_empty or poly.distance(obstacles) > margin


@pytest.fixture(scope="module")
def scene(paper_lot):
    rng = np.random.default_rng(3)
    occ = rng.random(paper_lot.n_spots) < 0.6
    poses, dims = paper_lot.spot_poses[occ], paper_lot.spot_dims[occ]
    # one static vehicle parked askew in a vacant spot
    k = int(np.nonzero(~occ)[0][0])
    veh = np.array([[paper_lot.spot_poses[k, 0] + 0.2, paper_lot.spot_poses[k, 1], paper_lot.spot_poses[k, 2] + 0.1]])
    poses = np.concatenate([poses, veh])
    dims = np.concatenate([dims, [[L, W]]])
    world = StaticWorld(paper_lot, poses, dims, L, W, CollisionSettings())
    obstacles = unary_union([footprint(*p, *d) for p, d in zip(poses, dims, strict=True)])
    return world, Polygon(paper_lot.boundary), obstacles


@pytest.mark.parametrize("margin", [0.0, 0.15])
def test_free_never_reports_a_colliding_pose(scene, margin):
    world, lot_poly, obstacles = scene
    rng = np.random.default_rng(11)
    n = 4000
    poses = np.column_stack([rng.uniform(-1, 44, n), rng.uniform(-1, 42.5, n), rng.uniform(-math.pi, math.pi, n)])
    free = world.free(poses, margin)
    truth = np.array([oracle_free(footprint(*p), lot_poly, obstacles, margin) for p in poses])
    assert not np.any(free & ~truth), "the planner accepted a pose the oracle rejects"
    # the exact stage decides near obstacles, so the check is not needlessly conservative either
    assert np.mean(free == truth) > 0.995
    assert 0.2 < free.mean() < 0.8  # the sample mixes free and colliding poses


def test_exact_stage_matches_oracle_near_obstacles(scene):
    world, lot_poly, obstacles = scene
    rng = np.random.default_rng(5)
    # poses hugging the spot rows: all go through the exact stage
    n = 1500
    poses = np.column_stack([rng.uniform(10, 33, n), rng.uniform(6, 36, n), rng.uniform(-math.pi, math.pi, n)])
    got = world.exact_free(poses, 0.0)
    truth = np.array([oracle_free(footprint(*p), lot_poly, obstacles, 0.0) for p in poses])
    assert np.array_equal(got, truth)


def test_clearance_is_a_lower_bound(scene):
    world, lot_poly, obstacles = scene
    blocked = unary_union([obstacles, box(-50, -50, 100, 100).difference(lot_poly)])
    rng = np.random.default_rng(2)
    pts = np.column_stack([rng.uniform(0, 43, 3000), rng.uniform(0, 41.5, 3000)])
    clr = world.clearance(pts)
    true = np.array([0.0 if blocked.contains(Point(p)) else blocked.distance(Point(p)) for p in pts])
    assert np.all(clr <= true + 1e-9)
    assert np.mean(true - clr) < 0.35  # and not uselessly loose
    assert clr.max() > 2.0


def test_nan_pose_is_not_free(scene):
    world, _, _ = scene
    poses = np.array([[21.5, 20.0, -1.57], [np.nan, 20.0, 0.0], [21.5, np.inf, 0.0]])
    assert world.free(poses, 0.1).tolist() == [True, False, False]


def test_merge_rects_keeps_the_union(paper_lot):
    rng = np.random.default_rng(0)
    for _ in range(10):
        occ = rng.random(paper_lot.n_spots) < 0.7
        p, d = paper_lot.spot_poses[occ], paper_lot.spot_dims[occ]
        mp, md = merge_rects(p, d)
        a = unary_union([footprint(*q, *e) for q, e in zip(p, d, strict=True)])
        b = [footprint(*q, *e) for q, e in zip(mp, md, strict=True)]
        assert len(b) < len(p)
        assert a.symmetric_difference(unary_union(b)).area < 1e-6
        assert abs(sum(x.area for x in b) - a.area) < 1e-6  # no overlaps


def test_merge_after_a_cached_base_gives_the_full_merge(paper_lot):
    """The base (occupied spots) merged once and cached, then the vehicles after it: the same rectangles in the same
    order as the full merge — with noisy vehicle boxes (the fast path), with boxes parallel to the spots (the full
    merge runs), and with a vehicle box that is exactly a vacant spot's (it merges with its neighbours)."""
    rng = np.random.default_rng(3)
    cache: dict = {}
    fast = 0
    for trial in range(30):
        occ = rng.random(paper_lot.n_spots) < 0.6
        p, d = paper_lot.spot_poses[occ], paper_lot.spot_dims[occ]
        k = int(rng.integers(0, 6))
        vp = np.column_stack([rng.uniform(5, 40, k), rng.uniform(5, 40, k), rng.uniform(-3.1, 3.1, k)])
        vd = np.column_stack([rng.uniform(4.0, 5.0, k), rng.uniform(1.7, 2.0, k)])
        if trial % 3 == 1 and k:  # parked exactly at a spot's heading
            vp[:, 2] = p[0, 2]
        if trial % 3 == 2 and (~occ).any():  # exactly a vacant spot's rectangle: a merge the fast path must not skip
            j = int(np.nonzero(~occ)[0][0])
            vp = np.vstack([vp, paper_lot.spot_poses[j]])
            vd = np.vstack([vd, paper_lot.spot_dims[j]])
        poses, dims = np.vstack([p, vp]), np.vstack([d, vd])
        want = merge_rects(poses, dims)
        got = merge_rects_after(poses, dims, len(p), cache)
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
        fast += trial % 3 == 0 and k > 0
    assert fast >= 5


def test_non_convex_lot_boundary(paper_lot):
    """An L-shaped lot: the boundary test must reject footprints over the notch."""
    from avp_world.lot import LotMap

    poly = np.array([[0, 0], [30, 0], [30, 15], [15, 15], [15, 30], [0, 30]], dtype=float)
    lot = LotMap(name="l", boundary=poly, entrance=np.array([1.0, 1.0]), spots=paper_lot.spots[:0],
                 roads=paper_lot.roads[:1])
    world = StaticWorld(lot, np.zeros((0, 3)), np.zeros((0, 2)), L, W)
    rng = np.random.default_rng(8)
    poses = np.column_stack([rng.uniform(0, 30, 3000), rng.uniform(0, 30, 3000), rng.uniform(-3.2, 3.2, 3000)])
    lot_poly = Polygon(poly)
    for m in (0.0, 0.2):
        got = world.free(poses, m)
        truth = np.array([oracle_free(footprint(*p), lot_poly, Polygon(), m) for p in poses])
        assert not np.any(got & ~truth)
        assert np.mean(got == truth) > 0.99


# ------------------------------------------------------------------------------------------------ dynamic


def _pred_vehicle(agent_id, poses, length=L, width=W):
    return PredictedTrajectory(agent_id=agent_id, poses=np.asarray(poses, float), dt=0.1, length=length, width=width)


def test_dynamic_time_indexing_and_hold_last_pose():
    # a car crossing x = 10 from south to north at 1 m per step, 5 steps, then it holds its last pose
    car = _pred_vehicle(1, [[10.0, -5.0 + k, math.pi / 2] for k in range(1, 6)])
    dyn = DynamicObstacles([car], L, W, vehicle_margin=0.0)
    ego_still = np.array([[10.0, 0.0, 0.0]])
    # pose index k - 1 at time index k: at k = 2 the car (centre y = -3, half length 2.3) reaches y = -0.7,
    # inside the ego's |y| <= 0.925; at k = 1 (y = -4, up to -1.7) it does not
    assert dyn.first_collision(ego_still) == 2
    far = np.array([[30.0, 0.0, 0.0]])
    assert dyn.first_collision(far) == -1
    # after the prediction ends the car holds y = 0: an ego arriving there later still collides
    ego_late = np.array([[30.0, 0.0, 0.0]] * 20 + [[10.0, 0.0, 0.0]])
    assert dyn.first_collision(ego_late) == 20


def test_dynamic_matches_shapely_oracle():
    rng = np.random.default_rng(4)
    t = 30
    veh = [_pred_vehicle(i, np.column_stack([rng.uniform(0, 20, t), rng.uniform(0, 20, t),
                                             rng.uniform(-3, 3, t)])) for i in range(3)]
    ped = PredictedTrajectory(agent_id=9, poses=np.column_stack([rng.uniform(0, 20, t), rng.uniform(0, 20, t),
                                                                 np.zeros(t)]), dt=0.1, is_pedestrian=True,
                              radius=0.4)
    vm, pm = 0.3, 0.4
    dyn = DynamicObstacles([*veh, ped], L, W, vehicle_margin=vm, pedestrian_margin=pm)
    for trial in range(20):
        ego = np.column_stack([rng.uniform(0, 20, t + 1), rng.uniform(0, 20, t + 1), rng.uniform(-3, 3, t + 1)])
        ego[0] = (100.0, 100.0, 0.0)  # start far away: nominal margins (see the next test for the relaxation)
        hits = set(dyn.collision_steps(ego).tolist())
        for k in range(1, t + 1):
            fp = footprint(*ego[k])
            hit = any(fp.distance(footprint(*v.poses[k - 1])) <= vm for v in veh)
            hit |= fp.distance(Point(ped.poses[k - 1, :2])) <= ped.radius + pm
            if hit:  # the planner may be more conservative (SAT with margin) but never less
                assert k in hits, (trial, k)
            elif k in hits:
                gaps = [fp.distance(footprint(*v.poses[k - 1])) for v in veh]
                assert min(gaps) <= vm * math.sqrt(2) + 1e-9 or fp.distance(Point(ped.poses[k - 1, :2])) <= (
                    ped.radius + pm + 1e-9)


def test_margin_relaxed_for_an_agent_already_that_close():
    """A stopped car 0.2 m from the ego (nominal margin 0.3): standing still or moving away is allowed,
    closing in (or any overlap) is not; a car that is far at first keeps the nominal margin."""
    stopped = _pred_vehicle(1, [[0.0, W + 0.2, 0.0]] * 10)  # parallel, 0.2 m to the ego's left
    dyn = DynamicObstacles([stopped], L, W, vehicle_margin=0.3)
    ego0 = np.array([0.0, 0.0, 0.0])
    assert dyn.first_collision(np.array([ego0] * 5)) == -1
    away = np.array([[0.0, -0.1 * k, 0.0] for k in range(6)])
    assert dyn.first_collision(away) == -1
    closer = np.array([[0.0, 0.1 * k, 0.0] for k in range(6)])
    assert dyn.first_collision(closer) == 1
    far_start = np.array([[0.0, -5.0, 0.0]] + [[0.0, 0.0, 0.0]] * 5)
    assert dyn.first_collision(far_start) == 1  # 0.2 m < 0.3 m nominal: a collision when arriving there


def test_overlapping_obstacles_raster_as_their_union(paper_lot):
    """Obstacles that overlap (a car sticking out of its spot, two crossing rectangles) are one obstacle in the
    raster: every grid cell whose centre lies in the union (shapely) is occupied — fillPoly with several contours
    fills even-odd, which would leave the overlaps as free holes."""
    k = paper_lot.spot_index(21)
    sp = paper_lot.spot_poses[k]
    poses = np.array([sp, [sp[0] + 1.0, sp[1] + 0.5, sp[2]], [20.0, 20.0, 0.0], [20.0, 20.0, math.pi / 2]])
    dims = np.array([paper_lot.spot_dims[k], [L, W], [6.0, 2.0], [6.0, 2.0]])
    world = StaticWorld(paper_lot, poses, dims, L, W, CollisionSettings())
    union = unary_union([footprint(*p, *d) for p, d in zip(poses, dims, strict=True)])
    h, w = world.grid.shape
    jj, ii = np.meshgrid(np.arange(w), np.arange(h))
    cx, cy = world.origin[0] + (jj + 0.5) * world.res, world.origin[1] + (ii + 0.5) * world.res
    x0, y0, x1, y1 = union.bounds
    box_cells = (cx > x0) & (cx < x1) & (cy > y0) & (cy < y1)
    inside = np.array([union.contains(Point(x, y)) for x, y in zip(cx[box_cells], cy[box_cells], strict=True)])
    assert inside.sum() > 1000 and world.grid[box_cells][inside].all()

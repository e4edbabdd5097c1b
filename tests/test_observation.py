"""Tests of the occlusion-aware observation model (paper §III-A): ``avp_sensing.observation``.

The expected values come from shapely (an independent geometry engine) or are worked out by hand;
none are produced by the code under test.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import shapely
from shapely import affinity
from shapely.geometry import LinearRing, Point, Polygon, box

from avp_sensing.observation import RayCaster, SensorConfig, classify_world
from avp_world.geometry import rect_corners, rect_inside_rect
from avp_world.lot import LotMap, load_bundled_lot

LOT = load_bundled_lot("paper_lot")
LOT_POLY = Polygon(LOT.boundary)
SPOT_POLYS = [Polygon(c) for c in LOT.spot_corners]
QUAD_SEGS = 1024  # Point.buffer resolution of the disc / ellipse oracle (sagitta ~3.4e-6 m at 11.5 m)
GRAZE_TOL = 1e-6  # rays passing this close to a vehicle corner are degenerate (tangent) cases


# ------------------------------------------------------------------------------------ scene helpers


def _rect(x: float, y: float, th: float, length: float, width: float) -> Polygon:
    """Oriented rectangle built with shapely only (independent of avp_world.geometry)."""
    r = box(x - length / 2, y - width / 2, x + length / 2, y + width / 2)
    return affinity.rotate(r, th, origin=(x, y), use_radians=True)


def _corners(poly: Polygon) -> np.ndarray:
    """(4, 2) corners of a shapely rectangle, in boundary order."""
    return np.asarray(poly.exterior.coords)[:4]


def _region_world(cfg: SensorConfig, pose: np.ndarray) -> Polygon:
    """Q_t as a shapely polygon: Q0 built in the ego frame, rotated by the heading, moved to the ego."""
    ox, oy = cfg.offset
    if cfg.shape == "disc":
        q0 = Point(ox, oy).buffer(cfg.radius, quad_segs=QUAD_SEGS)
    elif cfg.shape == "ellipse":
        q0 = affinity.scale(Point(0, 0).buffer(1.0, quad_segs=QUAD_SEGS), cfg.semi_major, cfg.semi_minor)
        q0 = affinity.translate(q0, ox, oy)
    elif cfg.shape == "rectangle":
        q0 = box(ox - cfg.length / 2, oy - cfg.width / 2, ox + cfg.length / 2, oy + cfg.width / 2)
    else:
        q0 = Polygon(np.asarray(cfg.vertices, dtype=float) + [ox, oy])
    q = affinity.rotate(q0, pose[2], origin=(0, 0), use_radians=True)
    return affinity.translate(q, pose[0], pose[1])


def _region_tol(cfg: SensorConfig) -> float:
    """How far the shapely region may be from the exact one along a ray."""
    if cfg.shape in ("disc", "ellipse"):
        big = cfg.radius if cfg.shape == "disc" else max(cfg.semi_major, cfg.semi_minor)
        return 2.0 * big * (1.0 - math.cos(math.pi / (4 * QUAD_SEGS))) + 1e-6
    return 1e-6


def _random_scene(rng: np.random.Generator, n_max: int = 40):
    """Random non-overlapping vehicles (some parked), an ego pose clear of them, random pedestrians."""
    n_target = int(rng.integers(0, n_max + 1))
    polys: list[Polygon] = []
    tries = 0
    while len(polys) < n_target and tries < 4000:
        tries += 1
        length, width = rng.uniform(3.5, 5.2), rng.uniform(1.6, 2.1)
        if rng.random() < 0.4:  # parked (or nearly parked) in a random spot
            sp = LOT.spots[int(rng.integers(LOT.n_spots))]
            x, y = sp.x + rng.normal(0, 0.1), sp.y + rng.normal(0, 0.1)
            th = sp.heading + rng.normal(0, 0.03)
        else:
            x, y, th = rng.uniform(1, 42), rng.uniform(1, 40.5), rng.uniform(-np.pi, np.pi)
        p = _rect(x, y, th, length, width)
        if not LOT_POLY.contains(p) or any(p.distance(q) < 1e-3 for q in polys):
            continue
        polys.append(p)
    while True:
        if rng.random() < 0.3:  # along the middle road
            pose = np.array([rng.uniform(19, 24), rng.uniform(4, 38), rng.uniform(-np.pi, np.pi)])
        else:
            pose = np.array([rng.uniform(0.1, 42.9), rng.uniform(0.1, 41.4), rng.uniform(-np.pi, np.pi)])
        pt = Point(pose[:2])
        if LOT_POLY.exterior.distance(pt) > 0.05 and all(q.distance(pt) > 0.05 for q in polys):
            break
    n_ped = int(rng.integers(0, 11))
    peds = np.column_stack([rng.uniform(0, 43, n_ped), rng.uniform(0, 41.5, n_ped)])
    radii = rng.uniform(0.2, 0.6, n_ped)
    corners = np.array([_corners(p) for p in polys]).reshape(-1, 4, 2)
    return pose, polys, corners, peds, radii


def _check_against_shapely(cfg: SensorConfig, pose, polys, corners, peds, radii) -> dict:
    """Cast with the code under test and compare every ray with a shapely oracle.

    Returns counts (rays checked / skipped as degenerate) for the caller to assert on.
    """
    caster = RayCaster(LOT, cfg)
    scan = caster.cast(pose, corners, peds, radii)
    n = cfg.n_ray
    tol = _region_tol(cfg)
    o = pose[:2]
    opt = Point(o)
    ang = pose[2] + np.arange(n) * (2 * np.pi / n)
    d = np.column_stack([np.cos(ang), np.sin(ang)])
    region = _region_world(cfg, pose)
    reach = float(np.max(np.hypot(*(np.asarray(region.exterior.coords) - o).T))) + 1.0
    lines = shapely.linestrings(np.stack([np.broadcast_to(o, (n, 2)), o + reach * d], axis=1))

    n_veh = len(polys)
    cand = np.full((n, 2 + n_veh), np.inf)  # nearest hit distance per ray: [dL, dQ, dV_0..]
    cand[:, 0] = shapely.distance(opt, shapely.intersection(lines, LinearRing(LOT.boundary)))
    cand[:, 1] = shapely.distance(opt, shapely.intersection(lines, region.exterior))
    rings = np.array([p.exterior for p in polys], dtype=object)
    if n_veh:
        ri, vi = shapely.STRtree(rings).query(lines, predicate="intersects")
        cand[ri, 2 + vi] = shapely.distance(opt, shapely.intersection(lines[ri], rings[vi]))
    cand[np.isnan(cand)] = np.inf
    assert np.isfinite(cand[:, 1]).all()

    exp_range = cand.min(axis=1)
    which = cand.argmin(axis=1)
    exp_hit = np.where(which >= 2, which - 2, -1)
    srt = np.sort(cand, axis=1)
    tie = srt[:, 1] - srt[:, 0] <= 2 * tol
    segs = shapely.linestrings(np.stack([np.broadcast_to(o, (n, 2)), o + exp_range[:, None] * d], axis=1))
    if n_veh:
        graze = shapely.distance(segs, shapely.multipoints(corners.reshape(-1, 2))) <= GRAZE_TOL
    else:
        graze = np.zeros(n, dtype=bool)
    ok = ~(tie | graze)

    # ranges, end points and hit vehicles: strict on every non-degenerate ray
    np.testing.assert_allclose(scan.ranges[ok], exp_range[ok], rtol=0, atol=tol)
    np.testing.assert_array_equal(scan.hit_vehicle[ok], exp_hit[ok])
    np.testing.assert_allclose(scan.endpoints[ok], o + exp_range[ok, None] * d[ok], rtol=0, atol=tol)
    np.testing.assert_allclose(np.cos(scan.angles), d[:, 0], atol=1e-12)
    np.testing.assert_allclose(np.sin(scan.angles), d[:, 1], atol=1e-12)

    # longest plausible segment of a degenerate ray: up to the runner-up obstacle
    alt_len = np.minimum(srt[:, 1], cand[:, 1]) + 2 * tol
    alt = shapely.linestrings(np.stack([np.broadcast_to(o, (n, 2)), o + alt_len[:, None] * d], axis=1))[~ok]

    # seen vehicles
    sure = np.zeros(n_veh, dtype=bool)
    sure[exp_hit[ok & (exp_hit >= 0)]] = True
    maybe = sure.copy()
    if n_veh and len(alt):
        ai, vi = shapely.STRtree(rings).query(alt, predicate="dwithin", distance=GRAZE_TOL)
        maybe[vi] = True
    assert scan.seen_vehicles.shape == (n_veh,)
    assert scan.seen_vehicles[sure].all()
    assert not scan.seen_vehicles[~maybe].any()

    # seen spots: shapely intersects, with a 2*tol band around each spot treated as undecidable
    mitre = shapely.BufferJoinStyle.mitre
    shrunk = [p.buffer(-2 * tol, join_style=mitre) for p in SPOT_POLYS]
    grown = [p.buffer(2 * tol, join_style=mitre) for p in SPOT_POLYS]
    sure_s = np.zeros(LOT.n_spots, dtype=bool)
    maybe_s = np.zeros(LOT.n_spots, dtype=bool)
    sure_s[np.unique(shapely.STRtree(shrunk).query(segs[ok], predicate="intersects")[1])] = True
    maybe_s[np.unique(shapely.STRtree(grown).query(segs[ok], predicate="intersects")[1])] = True
    if len(alt):
        maybe_s[np.unique(shapely.STRtree(grown).query(alt, predicate="intersects")[1])] = True
    assert scan.seen_spots.shape == (LOT.n_spots,)
    np.testing.assert_array_equal(scan.seen_spots[sure_s], True)
    np.testing.assert_array_equal(scan.seen_spots[~maybe_s], False)

    # seen pedestrians: distance <= radius
    n_ped = len(radii)
    assert scan.seen_pedestrians.shape == (n_ped,)
    if n_ped:
        pts = shapely.points(peds)
        dmin = shapely.distance(segs[ok][:, None], pts[None, :]).min(axis=0, initial=np.inf)
        dalt = shapely.distance(alt[:, None], pts[None, :]).min(axis=0, initial=np.inf)
        np.testing.assert_array_equal(scan.seen_pedestrians[dmin < radii - 2 * tol], True)
        np.testing.assert_array_equal(scan.seen_pedestrians[np.minimum(dmin, dalt) > radii + 2 * tol], False)
    return {
        "rays": n,
        "skipped": int((~ok).sum()),
        "hits": int((exp_hit[ok] >= 0).sum()),
        "spots": int(sure_s.sum()),
        "unseen_spots": int((~maybe_s).sum()),
        "peds_seen": int(scan.seen_pedestrians.sum()),
    }


# ---------------------------------------------------------------------------------- oracle tests

N_CHUNKS, PER_CHUNK = 8, 25  # 200 random scenes


@pytest.mark.parametrize("chunk", range(N_CHUNKS))
def test_disc_matches_shapely_on_random_scenes(chunk):
    rng = np.random.default_rng(1000 + chunk)
    cfg = SensorConfig()  # the paper's default: disc of radius 11.5, 360 rays
    totals: dict[str, int] = {}
    for _ in range(PER_CHUNK):
        stats = _check_against_shapely(cfg, *_random_scene(rng))
        for k, v in stats.items():
            totals[k] = totals.get(k, 0) + v
    # the comparison is strict on all but a tiny fraction of rays, and the scenes are not trivial
    assert totals["skipped"] <= 0.01 * totals["rays"], totals
    assert totals["hits"] >= 0.1 * totals["rays"], totals
    assert totals["spots"] > 0 and totals["unseen_spots"] > 0 and totals["peds_seen"] > 0, totals


NON_DISC = [
    SensorConfig(n_ray=240, shape="rectangle", length=30.0, width=14.0, offset=(6.0, 1.0)),
    SensorConfig(n_ray=240, shape="ellipse", semi_major=16.0, semi_minor=7.0, offset=(4.0, -1.0)),
    SensorConfig(n_ray=240, shape="disc", radius=9.0, offset=(3.0, 2.0)),
    SensorConfig(  # non-convex, not centred on the ego
        n_ray=241,
        shape="polygon",
        vertices=((-3.0, -4.0), (14.0, -6.0), (9.0, 0.0), (16.0, 7.0), (-2.0, 5.0)),
        offset=(1.5, 0.5),
    ),
]


@pytest.mark.parametrize("cfg", NON_DISC, ids=lambda c: c.shape)
def test_other_sensing_regions_match_shapely(cfg):
    rng = np.random.default_rng(7)
    totals = {"rays": 0, "skipped": 0, "hits": 0}
    for _ in range(25):
        stats = _check_against_shapely(cfg, *_random_scene(rng))
        for k in totals:
            totals[k] += stats[k]
    assert totals["skipped"] <= 0.01 * totals["rays"], totals
    assert totals["hits"] >= 0.1 * totals["rays"], totals


def test_region_range_of_each_shape_by_hand():
    """Ranges in an empty, far-away-walled spot of the lot equal the region's extent along each ray."""
    pose = np.array([21.5, 20.75, 0.0])  # lot centre; the nearest wall is 20.75 m away
    empty = np.zeros((0, 4, 2))
    rect = RayCaster(LOT, SensorConfig(n_ray=4, shape="rectangle", length=10.0, width=4.0, offset=(2.0, 0.0)))
    np.testing.assert_allclose(rect.cast(pose, empty).ranges, [7.0, 2.0, 3.0, 2.0], atol=1e-12)
    ell = RayCaster(LOT, SensorConfig(n_ray=4, shape="ellipse", semi_major=8.0, semi_minor=3.0))
    np.testing.assert_allclose(ell.cast(pose, empty).ranges, [8.0, 3.0, 8.0, 3.0], atol=1e-12)
    disc = RayCaster(LOT, SensorConfig(n_ray=4, radius=5.0, offset=(3.0, 0.0)))
    np.testing.assert_allclose(disc.cast(pose, empty).ranges, [8.0, 4.0, 2.0, 4.0], atol=1e-12)
    # the disc is exact: every range equals the radius
    scan = RayCaster(LOT, SensorConfig()).cast(pose, empty)
    assert np.all(scan.ranges == 11.5)
    # heading rotates the region with the ego: rectangle facing north
    scan = rect.cast(np.array([21.5, 20.75, np.pi / 2]), empty)
    np.testing.assert_allclose(scan.ranges, [7.0, 2.0, 3.0, 2.0], atol=1e-12)
    np.testing.assert_allclose(scan.endpoints[0], [21.5, 27.75], atol=1e-12)


# ------------------------------------------------------------------------------- hand-made cases


def test_vehicle_ahead_blocks_and_pedestrians_do_not():
    caster = RayCaster(LOT, SensorConfig(n_ray=4))
    car = _corners(_rect(15.0, 20.0, 0.0, 4.0, 2.0))  # rear face at x = 13
    ped = np.array([[12.0, 20.0], [11.0, 25.0], [2.0, 20.0], [12.0, 20.5], [12.0, 20.5], [18.0, 20.0]])
    radii = np.array([0.3, 0.4, 0.5, 0.5, 0.4999, 0.5])
    scan = caster.cast(np.array([10.0, 20.0, 0.0]), car[None], ped, radii)
    # east: car at 3 m; north: 11.5; west: wall at 10 m; south: 11.5
    np.testing.assert_allclose(scan.ranges, [3.0, 11.5, 10.0, 11.5], atol=1e-12)
    np.testing.assert_array_equal(scan.hit_vehicle, [0, -1, -1, -1])
    np.testing.assert_array_equal(scan.seen_vehicles, [True])
    # ped 0 is on the east ray before the car (and does not block it); ped 1 is 1 m beside the north
    # ray with radius 0.4 (unseen); ped 2 is on the west ray, 8 m out, before the wall; ped 3 touches
    # the east ray (closed discs: seen), ped 4 misses it by 0.1 mm; ped 5 lies on the east ray's line but
    # behind the car (x = 18 > 17), so it is occluded
    np.testing.assert_array_equal(scan.seen_pedestrians, [True, False, True, True, False, False])


def test_empty_inputs_and_shapes():
    caster = RayCaster(LOT, SensorConfig(n_ray=36))
    scan = caster.cast(np.array([21.5, 20.0, 0.3]), np.zeros((0, 4, 2)), np.zeros((0, 2)), np.zeros(0))
    assert scan.ranges.shape == (36,) and scan.endpoints.shape == (36, 2) and scan.angles.shape == (36,)
    assert scan.hit_vehicle.dtype.kind == "i" and np.all(scan.hit_vehicle == -1)
    assert scan.seen_vehicles.shape == (0,) and scan.seen_pedestrians.shape == (0,)
    assert scan.seen_spots.shape == (LOT.n_spots,)
    assert np.all(scan.ranges == 11.5)
    assert np.all((scan.angles >= -np.pi) & (scan.angles < np.pi))
    # pedestrians may be omitted
    assert caster.cast(np.array([21.5, 20.0, 0.3]), np.zeros((0, 4, 2))).seen_pedestrians.shape == (0,)


def test_ego_inside_another_vehicle_sees_it_at_range_zero():
    caster = RayCaster(LOT, SensorConfig(n_ray=8))
    cars = np.array([_corners(_rect(5.0, 5.0, 0.3, 4.6, 1.85)), _corners(_rect(21.0, 20.0, 0.0, 4.6, 1.85))])
    scan = caster.cast(np.array([21.5, 20.2, 1.0]), cars)
    np.testing.assert_array_equal(scan.ranges, np.zeros(8))
    np.testing.assert_array_equal(scan.hit_vehicle, np.ones(8, dtype=int))
    np.testing.assert_array_equal(scan.seen_vehicles, [False, True])
    np.testing.assert_allclose(scan.endpoints, np.tile([21.5, 20.2], (8, 1)))


def test_ego_outside_the_lot_and_on_its_boundary():
    caster = RayCaster(LOT, SensorConfig(n_ray=4))
    scan = caster.cast(np.array([-5.0, 20.0, 0.0]), np.zeros((0, 4, 2)))
    # east: enters the lot after 5 m; other rays never cross dL -> the sensing disc
    np.testing.assert_allclose(scan.ranges, [5.0, 11.5, 11.5, 11.5], atol=1e-12)
    scan = caster.cast(np.array([0.0, 20.0, 0.0]), np.zeros((0, 4, 2)))
    np.testing.assert_array_equal(scan.ranges, np.zeros(4))


def test_spot_seen_when_a_ray_ends_inside_it():
    # a car straddling the aisle side of spot 10 (column 1, x in [12.5, 18], y in [7, 9.75]) stops the ray
    caster = RayCaster(LOT, SensorConfig(n_ray=1, radius=30.0))
    ego = np.array([21.5, 8.375, np.pi])  # ray 0 points west along the spot's centre line
    car = _corners(_rect(16.0, 8.375, np.pi / 2, 3.0, 1.0))  # faces at x = 16.5 and 15.5
    scan = caster.cast(ego, car[None])
    np.testing.assert_allclose(scan.ranges, [5.0], atol=1e-12)
    seen = np.flatnonzero(scan.seen_spots)
    np.testing.assert_array_equal(seen, [10])  # spot 10; spot 0 behind the car is hidden


# ------------------------------------------------------------------------------- classify_world


def test_classify_world_hand_cases():
    s3 = LOT.spots[3]  # column 0, heading east, 5.5 x 2.75 m
    centred = _corners(_rect(s3.x, s3.y, s3.heading, 4.6, 1.85))
    half_out = _corners(_rect(s3.x - 2.75, s3.y, s3.heading, 4.6, 1.85))  # half in the left road
    s13, s14 = LOT.spots[13], LOT.spots[14]  # neighbours in column 1, sharing an edge at y = 16.625
    straddle = _corners(_rect(s13.x, 0.5 * (s13.y + s14.y), s13.heading, 4.6, 1.85))
    occ, vspot = classify_world(LOT, np.array([centred, half_out, straddle]))
    assert occ.shape == (LOT.n_spots,) and occ.dtype == bool
    np.testing.assert_array_equal(np.flatnonzero(occ), [3])
    np.testing.assert_array_equal(vspot, [3, -1, -1])
    # a car exactly the size of the spot is inside it (closed sets, small tolerance)
    exact = _corners(_rect(s14.x, s14.y, s14.heading, s14.length, s14.width))
    occ, vspot = classify_world(LOT, exact[None])
    np.testing.assert_array_equal(np.flatnonzero(occ), [14])
    np.testing.assert_array_equal(vspot, [14])
    # no vehicles
    occ, vspot = classify_world(LOT, np.zeros((0, 4, 2)))
    assert not occ.any() and vspot.shape == (0,)


def test_classify_world_every_spot_parked():
    cars = np.array([_corners(_rect(s.x, s.y, s.heading, 4.6, 1.85)) for s in LOT.spots])
    moving = _corners(_rect(21.5, 20.0, -np.pi / 2, 4.6, 1.85))
    occ, vspot = classify_world(LOT, np.concatenate([cars, moving[None]]))
    assert occ.all()
    np.testing.assert_array_equal(vspot, list(range(LOT.n_spots)) + [-1])


@pytest.mark.parametrize("lot_name", ["paper_lot", "side_lot", "dlp_lot"])
def test_classify_world_matches_every_pair_and_shapely(lot_name):
    """The near-pair filter changes nothing: the all-pairs containment test and shapely agree on random cars."""
    lot = load_bundled_lot(lot_name)
    rng = np.random.default_rng(7)
    rows = rng.integers(0, lot.n_spots, 300)
    jitter = rng.normal(0.0, 0.35, (300, 3)) * [1.0, 1.0, 0.1]
    poses = lot.spot_poses[rows] + jitter
    lo, hi = lot.spot_poses[:, :2].min(0), lot.spot_poses[:, :2].max(0)
    free = np.column_stack([rng.uniform(lo, hi, (100, 2)), rng.uniform(-np.pi, np.pi, 100)])
    cars = rect_corners(np.vstack([poses, free]), 4.6, 1.85)
    occ, vspot = classify_world(lot, cars)
    every = rect_inside_rect(cars[:, None], lot.spot_corners[None], tol=1e-6)  # (N, S), no filter
    np.testing.assert_array_equal(occ, every.any(0))
    np.testing.assert_array_equal(vspot, np.where(every.any(1), every.argmax(1), -1))
    spots = [Polygon(c) for c in lot.spot_corners]
    for i, c in enumerate(cars):
        car = Polygon(c)
        if vspot[i] >= 0:
            assert spots[vspot[i]].buffer(1e-3).contains(car)
        else:
            assert not any(s.buffer(-1e-3).contains(car) for s in spots)
    assert 0 < (vspot >= 0).sum() < len(cars)  # both outcomes occur


def test_classify_world_overlapping_spots_lowest_row():
    lot = load_bundled_lot("paper_lot")
    s = lot.spots[5]
    twin = LotMap(name="twin", boundary=lot.boundary, entrance=lot.entrance, roads=lot.roads,
                  spots=(*lot.spots, dataclasses.replace(s, id=9999)))  # spot 5 twice, the copy last
    car = _corners(_rect(s.x, s.y, s.heading, 4.6, 1.85))
    occ, vspot = classify_world(twin, car[None])
    np.testing.assert_array_equal(np.flatnonzero(occ), [5, twin.n_spots - 1])
    np.testing.assert_array_equal(vspot, [5])


def test_the_occupancy_tracker_is_classify_world_step_after_step():
    """OccupancyTracker (tests again only the cars that moved) against classify_world of every car, over 60 steps
    in which some cars park, some leave their spots and some drive on, on a lot whose spot 5 is there twice
    (both rows occupied, the lowest named): the same arrays each step; a change in the number of cars too."""
    from avp_sensing.occupancy import OccupancyTracker

    lot = load_bundled_lot("paper_lot")
    twin = LotMap(name="twin", boundary=lot.boundary, entrance=lot.entrance, roads=lot.roads,
                  spots=(*lot.spots, dataclasses.replace(lot.spots[5], id=9999)))
    rng = np.random.default_rng(3)
    parked = twin.spot_poses[rng.choice(twin.n_spots, 40, replace=False)]
    parked[0] = twin.spot_poses[5]
    lo, hi = twin.spot_poses[:, :2].min(0), twin.spot_poses[:, :2].max(0)
    driving = np.column_stack([rng.uniform(lo, hi, (10, 2)), rng.uniform(-np.pi, np.pi, 10)])
    poses = np.vstack([parked, driving])
    tracker = OccupancyTracker(twin)
    left = parked_now = 0  # cars that left their spot, cars that parked
    prev = None
    for step in range(60):
        movers = rng.choice(len(poses), 6, replace=False)
        poses[movers] += rng.normal(0.0, 0.4, (6, 3)) * [1.0, 1.0, 0.05]  # some leave their spot
        back = rng.choice(len(poses), 3, replace=False)
        poses[back] = twin.spot_poses[rng.integers(0, twin.n_spots, 3)]  # some park
        if step == 30:
            poses = poses[:-2]  # two cars leave the lot
        cars = rect_corners(poses, 4.6, 1.85)
        occ, vspot = tracker.classify(cars)
        want_occ, want_spot = classify_world(twin, cars)
        np.testing.assert_array_equal(occ, want_occ)
        np.testing.assert_array_equal(vspot, want_spot)
        if prev is not None and len(prev) == len(vspot):
            left += int(((prev >= 0) & (vspot < 0)).sum())
            parked_now += int(((prev < 0) & (vspot >= 0)).sum())
        prev = vspot
        if step == 0:
            assert occ[5] and occ[twin.n_spots - 1] and vspot[0] == 5
    assert left >= 20 and parked_now >= 20


# ------------------------------------------------------------------------------- SensorConfig


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"n_ray": 0}, "n_ray"),
        ({"n_ray": 2.5}, "n_ray"),
        ({"n_ray": True}, "n_ray"),
        ({"shape": "cone"}, "shape"),
        ({"radius": 0.0}, "radius"),
        ({"radius": float("nan")}, "radius"),
        ({"radius": -1.0}, "radius"),
        ({"offset": (12.0, 0.0)}, "offset"),
        ({"offset": (float("nan"), 0.0)}, "offset"),
        ({"offset": (1.0,)}, "offset"),
        ({"shape": "rectangle", "length": 0.0}, "length"),
        ({"shape": "rectangle", "width": float("inf")}, "width"),
        ({"shape": "rectangle", "length": 4.0, "offset": (2.5, 0.0)}, "offset"),
        ({"shape": "ellipse", "semi_minor": float("nan")}, "semi_minor"),
        ({"shape": "ellipse", "semi_major": -2.0}, "semi_major"),
        ({"shape": "ellipse", "semi_major": 4.0, "semi_minor": 2.0, "offset": (3.0, 1.5)}, "offset"),
        ({"shape": "polygon"}, "vertices"),
        ({"shape": "polygon", "vertices": ((1.0, 1.0), (2.0, 1.0))}, "vertices"),
        ({"shape": "polygon", "vertices": ((1.0, -1.0), (3.0, -1.0), (3.0, 1.0), (1.0, 1.0))}, "vertices"),
        ({"shape": "polygon", "vertices": ((-1.0, -1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, 1.0))}, "vertices"),
        ({"shape": "polygon", "vertices": ((-1.0, -1.0), (1.0, -1.0), (float("nan"), 1.0))}, "vertices"),
    ],
)
def test_sensor_config_validate_names_the_field(kwargs, field):
    cfg = SensorConfig(**kwargs)
    with pytest.raises(ValueError, match=rf"\b{field}\b"):
        cfg.validate()
    with pytest.raises(ValueError, match=rf"\b{field}\b"):
        RayCaster(LOT, cfg)


def test_sensor_config_valid_shapes_pass():
    for cfg in [SensorConfig(), *NON_DISC]:
        assert cfg.validate() is cfg

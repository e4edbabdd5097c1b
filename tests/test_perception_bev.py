"""BEV reconstruction of §V-B (``avp_belief_map.bev``).

Pixel checks use an independent oracle: world points are projected into the crop here with plain
trigonometry (forward = heading -> +column, left -> +row, ParkPredict+'s convention) and the colour read
at that pixel; polygons for "which pixels may change" come from shapely. Scenes are hand-built
observations (so that which spot is observed / believed is known exactly) and World snapshots.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from shapely import affinity
from shapely.geometry import LineString, Point, Polygon, box

from avp_belief_map.belief import BeliefMap, observation_update, spot_indices
from avp_belief_map.bev import (
    COLOR_CANDIDATE,
    COLOR_DYNAMIC,
    COLOR_EMPTY_SPOT,
    COLOR_STATIC,
    COLOR_TARGET,
    BEVConfig,
    BEVRenderer,
    changed_boxes,
    exploration_points_circle,
    exploration_points_square,
    rank_exploration_points,
    trail_colors,
)
from avp_scenario.scenario import ScenarioParams, generate_paper_scenario
from avp_sim.core.world import World
from avp_world.lot import load_bundled_lot
from avp_world.types import Observation, ObservedVehicle

LOT = load_bundled_lot("paper_lot")
BLACK, GREY = (0, 0, 0), (193, 193, 193)
FINE = BEVConfig(size_px=400, m_per_px=0.1)  # ParkPredict+'s resolution: crisp pixel checks
DT = 0.1


def pixel_xy(point, pose, cfg: BEVConfig) -> tuple[float, float]:
    """Oracle: continuous (col, row) of a world point in the crop of a vehicle at ``pose``."""
    dx, dy = point[0] - pose[0], point[1] - pose[1]
    fwd = dx * math.cos(pose[2]) + dy * math.sin(pose[2])
    left = -dx * math.sin(pose[2]) + dy * math.cos(pose[2])
    return fwd / cfg.m_per_px + cfg.size_px / 2, left / cfg.m_per_px + cfg.size_px / 2


def pixel(point, pose, cfg: BEVConfig) -> tuple[int, int]:
    """Oracle: (row, col) of the pixel holding a world point (integer coordinates are pixel centres)."""
    c, r = pixel_xy(point, pose, cfg)
    return int(round(r)), int(round(c))


def color_at(img, point, pose, cfg) -> tuple[int, int, int] | None:
    r, c = pixel(point, pose, cfg)
    if not (0 <= r < cfg.size_px and 0 <= c < cfg.size_px):
        return None
    return tuple(int(v) for v in img[r, c])


def straight_vehicle(vid, pose, speed, length=4.6, width=1.85, n=41, static=False) -> ObservedVehicle:
    """A vehicle that drove straight at ``speed`` along its heading for the last (n - 1) dt."""
    p = np.asarray(pose, dtype=float)
    back = speed * DT * np.arange(n - 1, -1, -1)
    hist = np.column_stack([p[0] - back * math.cos(p[2]), p[1] - back * math.sin(p[2]), np.full(n, p[2])])
    return ObservedVehicle(id=vid, length=length, width=width, is_static=static, history=hist)


def make_obs(vehicles, vacant=(), occupied=(), ego=(21.5, 32.0, -math.pi / 2)) -> Observation:
    return Observation(step=40, dt=DT, ego_pose=np.array(ego, dtype=float), ego_length=4.6, ego_width=1.85,
                       ego_speed=0.0, vacant_spot_ids=np.array(vacant, dtype=np.int64),
                       occupied_spot_ids=np.array(occupied, dtype=np.int64), vehicles=tuple(vehicles))


# hand scene: target driving north on the middle road; ego at the top; a yellow car on the left road
TARGET = straight_vehicle(1000, (21.5, 15.0, math.pi / 2), 1.0)
OTHER = straight_vehicle(1001, (3.5, 20.0, -math.pi / 2), 2.0)
VACANT, OCCUPIED = (12, 22, 5), (13, 23)
PRIOR = np.full(LOT.n_spots, 0.5)
PRIOR[[11, 21]] = 0.9  # unobserved, believed occupied -> default car
PRIOR[[14, 24]] = 0.2  # unobserved, believed vacant -> green candidate
PRIOR[[22]] = 1.0  # believed occupied before, now observed vacant -> green
PRIOR[[23]] = 0.1  # believed vacant before, now observed occupied -> b~ = 1, but observed: no default car
B_TILDE = observation_update(PRIOR, spot_indices(LOT, VACANT), spot_indices(LOT, OCCUPIED))


def render(cfg=BEVConfig(), target=TARGET, vehicles=(TARGET, OTHER), b=B_TILDE, **kw):
    obs = make_obs(vehicles, VACANT, OCCUPIED, **kw)
    return BEVRenderer(LOT, cfg).render(obs, target, b), obs


def inside_crop(point, pose, cfg, margin_m=2.0) -> bool:
    r, c = pixel(point, pose, cfg)
    m = margin_m / cfg.m_per_px
    return m <= r < cfg.size_px - m and m <= c < cfg.size_px - m


@pytest.mark.parametrize("cfg", [BEVConfig(), FINE], ids=["100px", "400px"])
def test_spot_centres_default_cars_only_on_unobserved_believed_occupied(cfg):
    bev, obs = render(cfg)
    img = bev.image
    observed = set(VACANT) | set(OCCUPIED)
    checked = {"blue": 0, "green": 0, "black": 0}
    for k, s in enumerate(LOT.spots):
        if not inside_crop((s.x, s.y), TARGET.pose, cfg):
            continue
        col = color_at(img, (s.x, s.y), TARGET.pose, cfg)
        if B_TILDE[k] < 0.5:
            assert col == COLOR_EMPTY_SPOT, (s.id, col)
            checked["green"] += 1
        elif s.id in observed:  # observed occupied, no vehicle reported there: never a default car
            assert col == BLACK, (s.id, col)
            checked["black"] += 1
        else:
            assert col == COLOR_STATIC, (s.id, col)
            checked["blue"] += 1
    assert checked["green"] >= 5 and checked["black"] == 2 and checked["blue"] >= 20


def test_default_car_has_the_default_size():
    cfg = FINE
    bev, _ = render(cfg)
    s = LOT.spots[LOT.spot_index(11)]  # unobserved, b = 0.9
    u = np.array([math.cos(s.heading), math.sin(s.heading)])
    v = np.array([-u[1], u[0]])
    c = np.array([s.x, s.y])
    at = lambda p: color_at(bev.image, p, TARGET.pose, cfg)  # noqa: E731
    half_l, half_w = 4.97 / 2, 1.86 / 2
    assert at(c + (half_l - 0.2) * u) == COLOR_STATIC and at(c - (half_l - 0.2) * u) == COLOR_STATIC
    assert at(c + (half_w - 0.2) * v) == COLOR_STATIC and at(c - (half_w - 0.2) * v) == COLOR_STATIC
    assert at(c + (half_l + 0.15) * u) == BLACK and at(c + (half_w + 0.25) * v) == BLACK
    # an empty spot is drawn shrunk by 0.3 m: 0.5 m inside the spot edge is green, 0.1 m inside is not
    e = LOT.spots[LOT.spot_index(14)]
    ue = np.array([math.cos(e.heading), math.sin(e.heading)])
    ce = np.array([e.x, e.y])
    assert at(ce + (e.length / 2 - 0.5) * ue) == COLOR_EMPTY_SPOT
    assert at(ce + (e.length / 2 - 0.1) * ue) == BLACK


def test_roads_vehicles_and_trail_colours():
    cfg = FINE
    bev, obs = render(cfg)
    img = bev.image
    pose = TARGET.pose
    at = lambda p: color_at(img, p, pose, cfg)  # noqa: E731
    # road: the middle road 5 m ahead of the target is drivable and empty
    assert at((21.5, 20.0)) == GREY
    # the target (red, current pose on top) spans its length along +column, its width along +row
    assert at((21.5, 15.0 + 2.0)) == COLOR_TARGET and at((21.5, 15.0 - 2.0)) == COLOR_TARGET
    assert at((21.5 - 0.7, 15.0)) == COLOR_TARGET and at((21.5 - 1.3, 15.0)) != COLOR_TARGET
    r, c = pixel((21.5, 17.0), pose, cfg)
    assert r == 200 and c == 220  # heading north -> +column; the crop centre is pixel (200, 200)
    # trail: 4 s at 1 m/s; only the oldest pose covers 5.9 .. 6.3 m behind the current centre
    oldest = trail_colors(COLOR_TARGET, 10)[0]
    assert oldest == (127, 0, 0)
    assert at((21.5, 15.0 - 6.1)) == oldest
    # the other dynamic vehicle is yellow (full colour at its current pose, faded behind it)
    assert at((3.5, 20.0)) == COLOR_DYNAMIC
    faded = at((3.5, 20.0 + 2.3 + 2.0 * 3.0))  # 3 s ago it was 6 m further north
    assert faded is not None and faded != COLOR_DYNAMIC and faded[2] == 0 and 0 < faded[0] == faded[1] < 255
    # the ego (just another observed vehicle) is yellow
    assert at((21.5, 32.0)) == COLOR_DYNAMIC


def test_left_of_the_vehicle_is_plus_row():
    cfg = BEVConfig()
    bev, _ = render(cfg)
    # heading north, left = west: the left road (x = 3.5) lies at +row, the right column of spots at -row
    r_left, _ = pixel((3.5, 15.0), TARGET.pose, cfg)
    r_right, _ = pixel((39.5, 15.0), TARGET.pose, cfg)
    assert r_left > cfg.size_px / 2 > r_right
    assert tuple(bev.image[r_left, 50]) == GREY


def test_rotating_the_heading_rotates_the_image():
    cfg = BEVConfig()
    north = straight_vehicle(1000, (21.5, 15.0, math.pi / 2), 0.0)
    east = straight_vehicle(1000, (21.5, 15.0, 0.0), 0.0)
    img_n = render(cfg, target=north, vehicles=(north, OTHER))[0].image
    img_e = render(cfg, target=east, vehicles=(east, OTHER))[0].image
    # heading theta + pi/2: col' = row and row' = size - col (centre at pixel size/2)
    n = cfg.size_px
    rows, cols = np.mgrid[0:n, 1:n]
    agree = np.all(img_n[n - cols, rows] == img_e[rows, cols], axis=-1).mean()
    assert agree > 0.97  # edge pixels may round differently
    assert np.all(img_n == img_e, axis=-1).mean() < 0.8  # and the two crops really differ
    # the east-facing crop sees the middle road across the image (rows), the north-facing one along it
    assert tuple(img_n[50, 75]) == GREY and tuple(img_e[75, 50]) == GREY  # (21.5, 25): 10 m north


def test_candidates_and_marking_change_exactly_that_spot():
    cfg = BEVConfig()
    bev, obs = render(cfg)
    # oracle candidate set: b~ < beta and centre in the crop
    expected = sorted(s.id for k, s in enumerate(LOT.spots)
                      if B_TILDE[k] < 0.5 and inside_crop((s.x, s.y), TARGET.pose, cfg, margin_m=0.0))
    assert sorted(bev.candidate_spot_ids.tolist()) == expected
    assert {12, 22, 14, 24} <= set(expected) and 13 not in expected and 11 not in expected
    images = bev.images()
    assert images.shape == (len(expected) + 1, cfg.size_px, cfg.size_px, 3)
    np.testing.assert_array_equal(images[0], bev.image)
    for j, sid in enumerate(bev.candidate_spot_ids):
        s = LOT.spots[LOT.spot_index(int(sid))]
        marked = bev.candidate_images[j]
        assert color_at(marked, (s.x, s.y), TARGET.pose, cfg) == COLOR_CANDIDATE
        changed = np.argwhere(np.any(marked != bev.image, axis=-1))
        assert len(changed)
        # every changed pixel lies in the shrunk spot (shapely, in pixel space, 1 px tolerance), was green
        corners = [pixel_xy(q, TARGET.pose, cfg) for q in _rect(s.x, s.y, s.heading, s.length - 0.6, s.width - 0.6)]
        poly = Polygon(corners).buffer(1.0)
        assert all(poly.contains(Point(c, r)) for r, c in changed)
        assert np.all(bev.image[changed[:, 0], changed[:, 1]] == COLOR_EMPTY_SPOT)
        assert np.all(marked[changed[:, 0], changed[:, 1]] == COLOR_CANDIDATE)
        # the box handed to the CNN holds every changed pixel
        r0, r1, c0, c1 = bev.candidate_boxes[j]
        assert changed[:, 0].min() >= r0 and changed[:, 0].max() <= r1
        assert changed[:, 1].min() >= c0 and changed[:, 1].max() <= c1
        # the other candidates stay green in this image
        for other in bev.candidate_spot_ids:
            if other != sid:
                o = LOT.spots[LOT.spot_index(int(other))]
                if inside_crop((o.x, o.y), TARGET.pose, cfg, margin_m=0.5):
                    assert color_at(marked, (o.x, o.y), TARGET.pose, cfg) == COLOR_EMPTY_SPOT


def _rect(x, y, th, length, width):
    r = affinity.rotate(box(x - length / 2, y - width / 2, x + length / 2, y + width / 2), th, origin=(x, y),
                        use_radians=True)
    return list(r.exterior.coords)[:4]


def test_spot_under_another_vehicle_is_not_a_candidate():
    cfg = BEVConfig()
    s = LOT.spots[LOT.spot_index(12)]  # observed vacant, but a car is halfway into it
    intruder = straight_vehicle(1002, (s.x + 1.5, s.y, math.pi), 0.5)
    bev, _ = render(cfg, vehicles=(TARGET, OTHER, intruder))
    assert 12 not in bev.candidate_spot_ids
    assert color_at(bev.image, (s.x, s.y), TARGET.pose, cfg) == COLOR_DYNAMIC
    # the target's own footprint does not block a spot unless asked (ParkPredict+ behaviour)
    t = straight_vehicle(1000, (s.x + 1.5, s.y, math.pi), 0.5)
    assert 12 in render(cfg, target=t, vehicles=(t, OTHER))[0].candidate_spot_ids
    strict = replace(cfg, target_blocks_spot=True)
    assert 12 not in render(strict, target=t, vehicles=(t, OTHER))[0].candidate_spot_ids


def test_observed_static_vehicle_is_blue_and_not_doubled():
    cfg = FINE
    s = LOT.spots[LOT.spot_index(13)]
    parked = straight_vehicle(13, (s.x, s.y, s.heading), 0.0, static=True)
    bev, _ = render(cfg, vehicles=(TARGET, OTHER, parked))
    at = lambda p: color_at(bev.image, p, TARGET.pose, cfg)  # noqa: E731
    u = np.array([math.cos(s.heading), math.sin(s.heading)])
    assert at((s.x, s.y)) == COLOR_STATIC
    assert at(np.array([s.x, s.y]) + 2.2 * u) == COLOR_STATIC  # inside the 4.6 m car
    assert at(np.array([s.x, s.y]) + 2.42 * u) == BLACK  # beyond the 4.6 m car, inside l_def: no default car


def test_world_snapshot_bev():
    params = replace(ScenarioParams(), ego_start=(21.5, 20.0, -math.pi / 2), n_dynamic=(2, 2))
    world = World(LOT, generate_paper_scenario(LOT, 0, True, params))
    for _ in range(30):
        world.step(0.0, 0.0)
    obs = world.observe()
    dynamic = [v for v in obs.vehicles if not v.is_static]
    assert len(dynamic) == 2
    bm = BeliefMap.from_lot(LOT)
    bt = bm.observe(obs.vacant_spot_ids, obs.occupied_spot_ids)
    renderer = BEVRenderer(LOT)
    cfg = renderer.config
    seen = set(obs.vacant_spot_ids.tolist()) | set(obs.occupied_spot_ids.tolist())
    footprints = [Polygon(_rect(*v.pose, v.length, v.width)) for v in obs.vehicles]
    for v in dynamic:
        bev = renderer.render(obs, v, bt, bm.observed_mask)
        assert set(bev.candidate_spot_ids.tolist()) <= set(obs.vacant_spot_ids.tolist())
        for s in LOT.spots:
            if not inside_crop((s.x, s.y), v.pose, cfg) or any(f.buffer(0.5).contains(Point(s.x, s.y))
                                                               for f in footprints):
                continue
            col = color_at(bev.image, (s.x, s.y), v.pose, cfg)
            if s.id not in seen:
                assert col == COLOR_STATIC, (v.id, s.id)  # b = 0.5 >= beta, unobserved: default car
            elif s.id in obs.vacant_spot_ids:
                assert col == COLOR_EMPTY_SPOT, (v.id, s.id)
        for j, sid in enumerate(bev.candidate_spot_ids):
            s = LOT.spots[LOT.spot_index(int(sid))]
            assert color_at(bev.candidate_images[j], (s.x, s.y), v.pose, cfg) == COLOR_CANDIDATE


# ----------------------------------------------------------------------------------- exploration


def _centre_lines():
    return [(LineString([r.start, r.end]), r.heading) for r in LOT.roads]


def _check_points(points, expected_xy, center):
    got = sorted((round(p[0], 6), round(p[1], 6)) for p in points)
    assert got == sorted((round(x, 6), round(y, 6)) for x, y in expected_xy)
    for p in points:  # heading along the road, pointing away from the centre
        d = np.array([math.cos(p[2]), math.sin(p[2])])
        out = d @ (p[:2] - center)
        if abs(out) < 1e-9:  # the road only touches the region here: both directions are given
            assert sum(np.allclose(q[:2], p[:2]) and abs(math.cos(q[2] - p[2]) + 1) < 1e-9 for q in points) == 1
        else:
            assert out > 0
        assert any(abs(math.sin(p[2] - th)) < 1e-9 and line.distance(Point(p[0], p[1])) < 1e-9
                   for line, th in _centre_lines())


@pytest.mark.parametrize("center,radius", [((21.5, 15.0), 11.5), ((10.0, 30.0), 11.5), ((21.5, 20.0), 8.0)])
def test_exploration_points_on_circle(center, radius):
    c = np.array(center)
    pts = exploration_points_circle(LOT, c, radius)
    ring = Point(*c).buffer(radius, quad_segs=4096).exterior
    expected = []
    for line, _ in _centre_lines():
        inter = line.intersection(ring)
        expected += [(g.x, g.y) for g in getattr(inter, "geoms", [inter]) if not g.is_empty]
    got = sorted(set(map(tuple, np.round(pts[:, :2], 3))))
    assert got == sorted(set(map(tuple, np.round(expected, 3))))
    assert np.allclose(np.hypot(*(pts[:, :2] - c).T), radius)
    _check_points(pts, [tuple(p) for p in pts[:, :2]], c)


def test_exploration_points_on_square_boundary():
    pose = np.array([21.5, 15.0, math.pi / 2])  # square y in [-5, 35]: the 3 vertical roads cross y = 35
    pts = exploration_points_square(LOT, pose, 20.0)
    _check_points(pts, [(3.5, 35.0), (21.5, 35.0), (39.5, 35.0)], pose[:2])
    assert np.allclose(pts[:, 2], math.pi / 2)
    # a square holding every centre line has no crossing (paper lot: why the circle is the default)
    assert len(exploration_points_square(LOT, np.array([21.5, 20.75, 0.3]), 30.0)) == 0


def test_exploration_ranking_prefers_alignment_then_distance():
    pose = np.array([0.0, 0.0, 0.0])
    pts = np.array([[0.0, 5.0, 0.0], [10.0, 0.0, 0.0], [3.0, 0.0, 0.0], [-4.0, 0.0, 0.0]])
    ranked = rank_exploration_points(pose, pts)
    np.testing.assert_array_equal(ranked[:, 0], [3.0, 10.0, 0.0, -4.0])


def test_bev_exploration_points_in_result():
    bev, _ = render(BEVConfig())
    expected = rank_exploration_points(TARGET.pose, exploration_points_circle(LOT, TARGET.pose, 11.5))
    np.testing.assert_allclose(bev.exploration_points, expected)
    assert len(expected) >= 2


def test_config_validation():
    with pytest.raises(ValueError, match="m_per_px"):
        BEVConfig(m_per_px=0.0).validate()
    with pytest.raises(ValueError, match="exploration_shape"):
        BEVConfig(exploration_shape="hexagon").validate()
    with pytest.raises(ValueError, match="b_tilde"):
        BEVRenderer(LOT).render(make_obs([TARGET]), TARGET, np.zeros(3))


def test_no_candidate_when_everything_is_believed_occupied():
    bev, _ = render(BEVConfig(), b=np.full(LOT.n_spots, 0.7))
    assert bev.candidate_spot_ids.shape == (0,) and bev.candidate_images.shape == (0, 100, 100, 3)
    assert bev.candidate_boxes.shape == (0, 4)
    assert not np.any(np.all(bev.image == COLOR_EMPTY_SPOT, axis=-1))


def test_changed_boxes_by_hand():
    base = np.zeros((6, 7, 3), dtype=np.uint8)
    imgs = np.repeat(base[None], 3, axis=0)
    imgs[0, 1:3, 2:5] = (128, 0, 128)
    imgs[1, 5, 0, 2] = 1
    np.testing.assert_array_equal(changed_boxes(imgs, base), [[1, 2, 2, 4], [5, 5, 0, 0], [0, -1, 0, -1]])
    assert changed_boxes(imgs[:0], base).shape == (0, 4)


@pytest.mark.parametrize(("lot_name", "resolution"), [("paper_lot", 0.25), ("side_lot", 0.3), ("dlp_lot", 0.5)])
def test_occupancy_grid_layout_against_shapely(lot_name, resolution):
    """debug/occupancy's cell -> spot table (each spot tests only its bounding box) against shapely."""
    import shapely

    from avp_perception.core.debug_views import grid_layout

    lot = load_bundled_lot(lot_name)
    layout = grid_layout(lot, resolution)
    c = layout.cell_centres()
    expect = np.full((layout.height, layout.width), -1)
    for i in range(lot.n_spots - 1, -1, -1):  # the lowest row wins where spots overlap
        expect[shapely.contains_xy(Polygon(lot.spot_corners[i]), c[..., 0], c[..., 1])] = i
    np.testing.assert_array_equal(layout.spot_row, expect)
    np.testing.assert_array_equal(layout.inside, shapely.contains_xy(Polygon(lot.boundary), c[..., 0], c[..., 1]))
    assert (layout.spot_row >= 0).sum() > lot.n_spots  # spots cover cells


def test_the_visible_polygons_are_those_whose_box_meets_the_image():
    """`BEVRenderer._visible` (corner by corner) against shapely: a polygon is drawn when its bounding box meets the
    image square [-1, size] grown by the one-pixel margin, corners on the edge included."""
    renderer = BEVRenderer(LOT)
    size = renderer.size
    rng = np.random.default_rng(5)
    centres = rng.uniform(-40, size + 40, size=(400, 1, 2))
    polys = centres + rng.uniform(-30, 30, size=(400, 4, 2))
    polys[0] = [[-3, -3], [-1, -3], [-1, -1], [-3, -1]]  # touches the grown image at one corner
    polys[1] = [[size + 0.5, 5], [size + 2, 5], [size + 2, 6], [size + 0.5, 6]]  # starts past the far edge
    image = box(-1, -1, size, size)
    expected = [box(*Polygon(p).bounds).intersects(image) for p in polys]
    assert renderer._visible(polys).tolist() == expected
    assert expected[0] and not expected[1] and 50 < sum(expected) < 390

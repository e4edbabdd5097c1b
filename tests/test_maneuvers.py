"""ParkSim's 8 parking maneuvers re-made for eq. (1) (avp_scenario.maneuvers), with shapely as the
independent geometry oracle: control bounds, exact replay, collision-free, end in the spot, world mapping."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from shapely.geometry import Point, Polygon, box
from shapely.ops import unary_union

import avp_scenario.maneuvers as mv
from avp_world.geometry import rect_corners, wrap_angle
from avp_world.kinematics import rollout_vehicle
from avp_world.vehicle import VehicleSpec

VEH = VehicleSpec()
SCENE = mv.SceneGeometry()
DT = 0.1
KEYS = mv.ALL_MANEUVERS


@pytest.fixture(scope="module")
def maneuvers():
    return {k: mv.generate_maneuver(k) for k in KEYS}


def _footprints(states: np.ndarray) -> list[Polygon]:
    return [Polygon(c) for c in rect_corners(states, VEH.length, VEH.width)]


def _spot_polygon(side: str) -> Polygon:
    """The canonical target spot, built here from the scene numbers (not from the module)."""
    y0 = SCENE.aisle_width / 2
    y1 = y0 + SCENE.spot_length
    w = SCENE.spot_width / 2
    return box(-w, -y1, w, -y0) if side == "near" else box(-w, y0, w, y1)


def _parked_cars(side: str):
    """Every other spot of both rows holds a 4.6 x 1.85 m car centred in it (axis-aligned boxes)."""
    yc = SCENE.aisle_width / 2 + SCENE.spot_length / 2
    cars = []
    for row, y in (("near", -yc), ("far", yc)):
        for k in range(-5, 6):
            if k == 0 and row == side:
                continue
            x = k * SCENE.spot_width
            cars.append(box(x - VEH.width / 2, y - VEH.length / 2, x + VEH.width / 2, y + VEH.length / 2))
    return unary_union(cars)


_HALF = SCENE.aisle_width / 2 + SCENE.spot_length
GEOFENCE = box(-10.0, -_HALF, 10.0, _HALF)


# ------------------------------------------------------------------------------------------- library


def test_eight_distinct_keys():
    assert len(KEYS) == 8 and len(set(KEYS)) == 8
    assert {k.side for k in KEYS} == {"near", "far"}
    assert {k.stop for k in KEYS} == {"before", "after"}
    assert {k.entry for k in KEYS} == {"head_in", "tail_in"}
    with pytest.raises(ValueError):
        mv.generate_maneuver(mv.ManeuverKey("near", "before", "sideways"))


def test_generation_is_fast_deterministic_and_cached():
    mv.generate_maneuver.cache_clear()
    t0 = time.perf_counter()
    first = {k: mv.generate_maneuver(k) for k in KEYS}
    elapsed = time.perf_counter() - t0
    assert elapsed < 60.0, f"generating the 8 maneuvers took {elapsed:.2f} s"
    for k in KEYS:
        assert mv.generate_maneuver(k) is first[k]  # cached
        assert not first[k].controls.flags.writeable and not first[k].states.flags.writeable
    mv.generate_maneuver.cache_clear()
    for k in KEYS:
        again = mv.generate_maneuver(k)
        assert np.array_equal(again.controls, first[k].controls)  # deterministic


# ------------------------------------------------------------------------------------ per maneuver


@pytest.mark.parametrize("key", KEYS, ids=lambda k: "-".join(k))
def test_controls_within_parking_limits(maneuvers, key):
    m = maneuvers[key]
    v, om = m.controls[:, 0], m.controls[:, 1]
    assert m.controls.ndim == 2 and m.controls.shape[1] == 2 and len(m.controls) > 10
    assert (np.abs(v) <= 2.0).all()
    assert (np.abs(om) <= np.abs(v) / VEH.min_turning_radius + 1e-9).all()
    acc = np.diff(np.concatenate([[0.0], v])) / DT  # starts from v = 0
    assert (np.abs(acc) <= 2.0 + 1e-9).all()
    assert v[-1] == 0.0  # ends at rest
    # every change of direction passes through a stop (v = 0)
    moving = np.nonzero(v != 0.0)[0]
    for a, b in zip(moving[:-1], moving[1:], strict=True):
        if np.sign(v[a]) != np.sign(v[b]):
            assert b - a >= 2 and (v[a + 1 : b] == 0.0).all()


@pytest.mark.parametrize("key", KEYS, ids=lambda k: "-".join(k))
def test_states_are_exactly_the_eq1_rollout(maneuvers, key):
    m = maneuvers[key]
    assert m.states.shape == (len(m.controls) + 1, 3)
    assert np.array_equal(m.states, rollout_vehicle(m.start, m.controls, DT))
    x0 = -4.0 if key.stop == "before" else 4.0
    assert np.array_equal(m.start, [x0, -SCENE.aisle_width / 4, 0.0])
    assert m.duration == pytest.approx(len(m.controls) * DT)


@pytest.mark.parametrize("key", KEYS, ids=lambda k: "-".join(k))
def test_ends_centred_in_the_spot_with_the_right_heading(maneuvers, key):
    m = maneuvers[key]
    final = m.states[-1]
    spot = _spot_polygon(key.side)
    assert _footprints(final[None])[0].within(spot)
    spot_heading = -math.pi / 2 if key.side == "near" else math.pi / 2
    want = spot_heading if key.entry == "head_in" else spot_heading + math.pi
    assert abs(wrap_angle(final[2] - want)) <= math.radians(3.0)
    cy = spot.centroid.y
    assert abs(final[0]) <= 0.15  # lateral (the spot axis is x = 0)
    assert abs(final[1] - cy) <= 0.3  # longitudinal


@pytest.mark.parametrize("key", KEYS, ids=lambda k: "-".join(k))
def test_never_touches_a_parked_car_nor_leaves_the_geofence(maneuvers, key):
    m = maneuvers[key]
    cars = _parked_cars(key.side)
    for k, fp in enumerate(_footprints(m.states)):
        assert not fp.intersects(cars), f"step {k} hits a parked car"
        assert fp.distance(cars) >= SCENE.clearance - 0.05, f"step {k}: clearance {fp.distance(cars):.3f} m"
        assert fp.within(GEOFENCE), f"step {k} leaves the geofence"


@pytest.mark.parametrize("key", KEYS, ids=lambda k: "-".join(k))
def test_enters_the_spot_forward_for_head_in_and_reversing_for_tail_in(maneuvers, key):
    m = maneuvers[key]
    spot = _spot_polygon(key.side)
    want = 1.0 if key.entry == "head_in" else -1.0
    inside = np.array([spot.contains(Point(s[0], s[1])) for s in m.states])
    assert inside[-1]
    entries = np.nonzero(~inside[:-1] & inside[1:])[0]  # steps that move the centre into the spot
    assert len(entries) >= 1
    for k in entries:
        assert np.sign(m.controls[k, 0]) == want
    v = m.controls[:, 0]
    assert np.sign(v[v != 0][-1]) == want  # the last motion is the final approach


def test_maneuvers_differ(maneuvers):
    for k, m in maneuvers.items():
        assert (m.start[0] < 0) == (k.stop == "before")
        if k.entry == "tail_in":
            assert (m.controls[:, 0] < 0).any(), f"{k} has no reverse segment"
        # the near spot is reached going south (y decreasing), the far one going north
        assert (m.states[-1, 1] < -3.5) == (k.side == "near")
    finals = {(np.sign(m.states[-1, 1]), round(2 * m.states[-1, 2] / math.pi)) for m in maneuvers.values()}
    assert len(finals) == 4  # 2 spots x 2 headings
    trajectories = [m.states for m in maneuvers.values()]
    for i in range(len(trajectories)):
        for j in range(i + 1, len(trajectories)):
            a, b = trajectories[i], trajectories[j]
            assert a.shape != b.shape or not np.allclose(a, b)
    # reversing into the near spot after overshooting needs no cusp, nor does heading into it from before
    assert maneuvers[mv.ManeuverKey("near", "before", "head_in")].n_cusps == 0
    assert maneuvers[mv.ManeuverKey("near", "after", "tail_in")].n_cusps == 0
    assert maneuvers[mv.ManeuverKey("near", "before", "tail_in")].n_cusps >= 1


# ------------------------------------------------------------------------------- ParkSim's pace


PARKSIM_PACE = 1.1  # m/s: the scenario generator's speed bound (ScenarioParams.maneuver_max_speed)


@pytest.fixture(scope="module")
def paced():
    return {k: mv.generate_maneuver(k, SCENE, VEH, DT, max_speed=PARKSIM_PACE, max_accel=2.0) for k in KEYS}


def _path_length(states: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(states[:, :2], axis=0), axis=1).sum())


def test_parksim_pace_lasts_about_one_second_per_metre(paced):
    """ParkSim's H-OBCA library runs N steps of dt = 0.1 s with N = the number of Hybrid A* warm-start samples,
    0.1 m apart (hobca_planner.py, hybrid_a_star.py MOTION_RESOLUTION): a maneuver of L m lasts about L s."""
    lengths = np.array([_path_length(m.states) for m in paced.values()])
    durations = np.array([m.duration for m in paced.values()])
    assert 0.95 <= lengths.sum() / durations.sum() <= 1.05  # library mean speed ~ 1 m/s
    assert ((lengths / durations > 0.8) & (lengths / durations < 1.2)).all()


@pytest.mark.parametrize("key", KEYS, ids=lambda k: "-".join(k))
def test_paced_maneuvers_keep_their_bounds_and_still_park(maneuvers, paced, key):
    m, fast = paced[key], maneuvers[key]
    v, om = m.controls[:, 0], m.controls[:, 1]
    assert (np.abs(v) <= PARKSIM_PACE + 1e-9).all() and np.abs(v).max() > PARKSIM_PACE - 0.05
    assert (np.abs(om) <= np.abs(v) / VEH.min_turning_radius + 1e-9).all()
    assert (np.abs(np.diff(np.concatenate([[0.0], v]))) / DT <= 2.0 + 1e-9).all() and v[-1] == 0.0
    assert np.array_equal(m.states, rollout_vehicle(m.start, m.controls, DT))
    assert m.duration > fast.duration + 1.0  # slower than the 2 m/s library
    assert _footprints(m.states[-1][None])[0].within(_spot_polygon(key.side))
    cars = _parked_cars(key.side)
    assert all(fp.distance(cars) >= SCENE.clearance - 0.05 and fp.within(GEOFENCE) for fp in _footprints(m.states))
    assert abs(_path_length(m.states) - _path_length(fast.states)) < 0.5  # same path, another speed


def test_speed_bounds_must_be_positive():
    with pytest.raises(ValueError, match="max_speed"):
        mv.generate_maneuver(KEYS[0], SCENE, VEH, DT, max_speed=0.0)


# ------------------------------------------------------------------------------------------ world


@pytest.mark.parametrize("key", KEYS, ids=lambda k: "-".join(k))
def test_maneuver_to_world_on_paper_lot_spot_12(paper_lot, maneuvers, key):
    m = maneuvers[key]
    spot = paper_lot.spots[paper_lot.spot_index(12)]
    assert (spot.x, spot.y) == (15.25, 13.875) and spot.heading == pytest.approx(math.pi)
    start_w, states_w = mv.maneuver_to_world(m, spot.pose, aisle_width=7.0, side=key.side)
    assert np.allclose(start_w, states_w[0])
    # the same controls replay the world states through eq. (1) (the map is rigid)
    assert np.allclose(rollout_vehicle(start_w, m.controls, DT), states_w, atol=1e-9)
    road = paper_lot.roads[1]  # middle road, x = 21.5, from y = 38 down to y = 3.5, 7 m wide
    assert road.start[0] == road.end[0] == 21.5
    if key.side == "near":  # the spot is on the right of a car going south
        assert abs(wrap_angle(start_w[2] + math.pi / 2)) < 1e-9
        lane = box(18.0, road.end[1], 21.5, road.start[1])
    else:  # same spot, across the aisle of a car going north
        assert abs(wrap_angle(start_w[2] - math.pi / 2)) < 1e-9
        lane = box(21.5, road.end[1], 25.0, road.start[1])
    assert _footprints(start_w[None])[0].within(lane)
    assert start_w[0] == pytest.approx(19.75 if key.side == "near" else 23.25)
    spot_poly = Polygon(paper_lot.spot_corners[paper_lot.spot_index(12)])
    assert _footprints(states_w[-1][None])[0].within(spot_poly)
    want = spot.heading if key.entry == "head_in" else spot.heading + math.pi
    assert abs(wrap_angle(states_w[-1, 2] - want)) <= math.radians(3.0)
    lot = Polygon(paper_lot.boundary)
    assert all(fp.within(lot) for fp in _footprints(states_w))


def test_maneuver_to_world_checks_its_arguments(maneuvers):
    m = maneuvers[mv.ManeuverKey("near", "before", "head_in")]
    with pytest.raises(ValueError):
        mv.maneuver_to_world(m, np.array([15.25, 13.875, math.pi]), aisle_width=7.0, side="far")
    with pytest.raises(ValueError):
        mv.maneuver_to_world(m, np.array([15.25, 13.875, math.pi]), aisle_width=5.0, side="near")


def test_identity_transform_for_the_canonical_spot(maneuvers):
    for k, m in maneuvers.items():
        start_w, states_w = mv.maneuver_to_world(m, mv.target_spot_pose(k.side), SCENE.aisle_width, k.side)
        assert np.allclose(start_w, m.start) and np.allclose(states_w[:, :2], m.states[:, :2])
        assert np.allclose(wrap_angle(states_w[:, 2] - m.states[:, 2]), 0.0, atol=1e-12)

"""ego_yield (avp_planner.core.ego_yield): the beacons egos of a fleet send each other, the channel's rule, their
messages, and the planner's test of being in the way of an ego with the right of way (shapely as the judge)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import Polygon
from shapely.ops import unary_union

from avp_motion.planner_types import Decision
from avp_planner.core.ego_yield import MAX_BEACON_POSES, beacon_of, heard_by, path_zones
from avp_world.geometry import rect_corners
from avp_world.types import Beacon, Observation, ObservedVehicle


def _straight(x0: float, y0: float, heading: float, length: float, step: float = 0.25) -> np.ndarray:
    s = np.arange(0.0, length + 1e-9, step)
    return np.stack([x0 + s * math.cos(heading), y0 + s * math.sin(heading), np.full_like(s, heading)], axis=1)


def _box(centre, half_length: float, half_width: float) -> Polygon:
    return Polygon(rect_corners(np.asarray(centre, float), 2 * half_length, 2 * half_width))


def test_path_zones_cover_the_cars_swept_footprint_up_to_reach_and_no_further():
    path = _straight(0.0, 0.0, 0.3, 20.0)
    zones = path_zones(path, 4.8, 2.0, 10.0, 0.25)
    union = unary_union([_box(*z) for z in zones])
    arc = np.arange(0.0, 10.0 + 1e-9, 0.25)
    for s in arc:  # the car anywhere on the first 10 m lies inside the zones (grown by the margin)
        pose = path[int(round(s / 0.25))]
        assert union.buffer(1e-9).contains(_box(pose, 2.4, 1.0)), s
    far = path[int(round(15.5 / 0.25))]  # 15.5 m on: its footprint is beyond the zones (10 m + 2.4 + 0.25)
    assert not union.intersects(_box(far, 2.4, 1.0))
    assert path_zones(np.zeros((0, 3)), 4.8, 2.0, 10.0, 0.25) == []


def test_the_channel_gives_an_ego_the_beacons_of_the_egos_before_it():
    b = [Beacon(e, np.zeros(3), True, np.zeros((0, 3))) for e in (2, 0, 1)]
    assert [x.ego for x in heard_by(b, 2)] == [0, 1]
    assert [x.ego for x in heard_by(b, 1)] == [0]
    assert heard_by(b, 0) == ()


def test_a_beacon_announces_the_plan_or_while_waiting_the_plan_it_is_blocked_on():
    plan, wanted = _straight(0, 0, 0, 5.0), _straight(0, 0, 1.0, 30.0, 0.1)
    driving = Decision("park", poses=plan, command=(1.0, 0.0), trace={"mode": "park"})
    b = beacon_of(3, [1.0, 2.0, 0.5], driving)
    assert b.ego == 3 and not b.waiting and np.array_equal(b.path, plan) and b.pose.tolist() == [1.0, 2.0, 0.5]
    idle = Decision("idle", poses=plan[:1], command=(0.0, 0.0), trace={"mode": "idle"}, wanted=wanted)
    b = beacon_of(0, plan[0], idle)
    assert b.waiting and np.array_equal(b.path, wanted[:MAX_BEACON_POSES]) and len(b.path) == MAX_BEACON_POSES


def _obs(ego_pose, vehicles=(), beacons=()) -> Observation:
    return Observation(step=50, dt=0.1, ego_pose=np.asarray(ego_pose, float), ego_length=4.8, ego_width=2.0,
                       ego_speed=0.0, vacant_spot_ids=np.zeros(0, np.int64), occupied_spot_ids=np.zeros(0, np.int64),
                       vehicles=tuple(vehicles), beacons=tuple(beacons))


def _car(vid: int, pose) -> ObservedVehicle:
    return ObservedVehicle(vid, 4.8, 2.0, False, np.repeat(np.asarray(pose, float)[None], 5, axis=0))


@pytest.mark.parametrize("waiting, seen, path_through, expected", [
    (True, True, True, True),     # it waits to drive where the ego stands: in its way
    (False, True, True, False),   # it drives: nothing to give way to
    (True, False, True, False),   # not seen: not what blocks the ego
    (True, True, False, False),   # its path passes elsewhere
])
def test_the_ego_is_in_the_way_of_a_waiting_sender_only_on_its_announced_path(paper_lot, waiting, seen,
                                                                                path_through, expected):
    from avp_planner.core.decision import EgoPlanner

    other = np.array([36.0, 6.0, 0.0])  # an ego with the right of way, facing east along the bottom aisle
    ego = np.array([42.0, 8.0, -math.pi / 2])  # this ego, across its way ahead (seed 29's corner, K = 4)
    path = _straight(*other[:2], 0.0, 15.0) if path_through else _straight(*other[:2], math.pi, 15.0)
    beacon = Beacon(0, other, waiting, path)
    obs = _obs(ego, [_car(900000, other)] if seen else [], [beacon])
    ways = EgoPlanner(paper_lot)._in_the_way_of(obs, ego)
    assert bool(ways) == expected
    if expected:  # the judge: the ego's footprint meets the sender's footprint along the first 10 m of its path
        swept = unary_union([_box(p, 2.4, 1.0) for p in path if math.hypot(*(p[:2] - other[:2])) <= 10.0])
        assert swept.intersects(_box(ego, 2.4, 1.0)) and ways[0][0].id == 900000


def test_beacons_cross_their_message_exactly_and_bad_ones_are_refused():
    pytest.importorskip("rclpy")
    from avp_common.conversions import MessageError, beacons_from_msg, beacons_to_msg

    rng = np.random.default_rng(0)
    beacons = [Beacon(i, rng.normal(size=3), bool(i % 2), rng.normal(size=(7 + i, 3))) for i in range(3)]
    msg = beacons_to_msg(12, 0.1, beacons)
    assert msg.step == 12
    back = beacons_from_msg(msg)
    assert [(b.ego, b.waiting) for b in back] == [(b.ego, b.waiting) for b in beacons]
    for got, sent in zip(back, beacons, strict=True):
        assert np.array_equal(got.pose, sent.pose) and np.array_equal(got.path, sent.path)  # float64: bit for bit
    for bad, needle in (([Beacon(0, np.zeros(3), True, np.zeros((0, 3)))] * 8, "8 beacons, at most 7"),
                        ([Beacon(0, np.zeros(3), True, np.zeros((MAX_BEACON_POSES + 1, 3)))], "path poses, at most"),
                        ([Beacon(0, np.array([np.nan, 0, 0]), True, np.zeros((1, 3)))], "beacon of ego 0: pose")):
        with pytest.raises(MessageError, match=needle):
            beacons_from_msg(beacons_to_msg(0, 0.1, bad))


def test_without_ego_yield_the_gridlock_of_seed_29_forms(paper_lot):
    """The paper lot's one ego-ego gridlock (bezier, K = 4, seed 29: egos 0 and 3 face to face at the east end from
    42.8 s, docs/results/fleet/README.md) forms without ego_yield, and nobody collides. With the rule (the shipped
    default) ego 3 gives way and none forms: tests/test_fleet_dds.py's `test_an_ego_gives_way_over_dds_as_in_process`
    asserts that on its in-process run (one run of four egos fewer in `make test`)."""
    from avp_episode.fleet import run_fleet_inproc
    from avp_episode.run_config import RunConfig, run_profile, sim_values

    cfg = RunConfig(t_final=50.0, planner_overrides={"decision.ego_yield": False})
    off = run_fleet_inproc(paper_lot, sim_values(cfg), [run_profile("bezier", cfg)] * 4, 29, True, cfg)
    assert not any(r["collision"] for r in off)
    spells = off[0]["gridlock_spells"]
    assert [s["members"] for s in spells] == [["ego:0", "ego:3"]] and spells[0]["start_s"] == pytest.approx(42.8)

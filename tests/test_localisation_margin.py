"""The lot boundary the ego plans against when its pose is an estimate (avp_collision.localisation): L shrunk by
k standard deviations, spots kept whole; exact sensing plans against L itself. Shapely is the oracle."""

import numpy as np
from shapely.geometry import Point, Polygon

from avp_collision.localisation import localisation_margin, localised_lot
from avp_collision.settings import CollisionSettings
from avp_collision.static import StaticWorld
from avp_world.lot import load_lot

COV = np.diag([0.15**2, 0.15**2, 0.025**2])


def test_margin_is_k_sigmas_and_zero_without_a_covariance():
    m = localisation_margin(COV, 4.8, 2.0, 2.0)
    assert abs(m - 2.0 * (0.15 + 0.5 * np.hypot(4.8, 2.0) * 0.025)) < 0.006
    assert localisation_margin(None, 4.8, 2.0, 2.0) == 0.0
    assert localisation_margin(COV, 4.8, 2.0, 0.0) == 0.0


def test_boundary_shrinks_in_the_aisles_but_every_spot_stays_inside():
    for name in ("paper_lot", "side_lot", "dlp_lot"):
        lot = load_lot(f"src/avp_world/avp_world/maps/{name}.yaml")
        shrunk = localised_lot(lot, 0.4)
        L, Lp = Polygon(lot.boundary), Polygon(shrunk.boundary)
        assert Lp.is_valid and Lp.within(L.buffer(1e-6))
        for c in lot.spot_corners:  # a spot at a wall can still be the goal
            assert Polygon(c).intersection(L).difference(Lp.buffer(1e-6)).area < 1e-6
        # away from the spots, a point 0.2 m from the wall is outside L' but inside L
        spots = [Polygon(c).buffer(0.5) for c in lot.spot_corners]
        ring = L.exterior
        probes = [ring.interpolate(t, normalized=True) for t in np.linspace(0, 1, 400, endpoint=False)]
        inner = [Point(p.x, p.y) for p in probes]
        moved = 0
        for p in inner:
            # step 0.2 m inward along the polygon's interior
            q = L.buffer(-0.2).exterior.interpolate(L.buffer(-0.2).exterior.project(p))
            if any(s.contains(q) for s in spots) or not L.contains(q):
                continue
            assert not Lp.contains(q), (name, q)
            moved += 1
        assert moved > 50, name


def test_planner_world_rejects_a_pose_near_the_wall_only_with_the_margin():
    lot = load_lot("src/avp_world/avp_world/maps/paper_lot.yaml")
    xmin, ymin, xmax, ymax = lot.bounds()
    empty = np.zeros((0, 3)), np.zeros((0, 2))
    pose = np.array([[0.5 * (xmin + xmax), ymin + 1.0 + 0.25, 0.0]])  # 0.25 m from the bottom wall
    exact = StaticWorld(lot, *empty, 4.8, 2.0, CollisionSettings())
    noisy = StaticWorld(localised_lot(lot, 0.4), *empty, 4.8, 2.0, CollisionSettings())
    assert Polygon(lot.boundary).contains(Point(pose[0, 0], pose[0, 1] - 1.0))
    assert exact.free(pose, 0.05).all()
    assert not noisy.free(pose, 0.05).any()


def test_the_localiser_covariance_crosses_the_message_and_exact_sends_none():
    from avp_common.conversions import observation_from_msg, observation_to_msg
    from avp_world.types import Observation

    base = dict(step=3, dt=0.1, ego_pose=np.array([1.0, 2.0, 0.3]), ego_length=4.8, ego_width=2.0, ego_speed=1.0,
                vacant_spot_ids=np.zeros(0, np.int64), occupied_spot_ids=np.zeros(0, np.int64))
    back = observation_from_msg(observation_to_msg(Observation(**base, ego_covariance=COV)))
    np.testing.assert_allclose(back.ego_covariance, COV)
    assert observation_from_msg(observation_to_msg(Observation(**base))).ego_covariance is None
    msg = observation_to_msg(Observation(**base, ego_covariance=COV))
    msg.ego_pose_covariance[4] = float("nan")
    import pytest

    from avp_common.conversions import MessageError
    with pytest.raises(MessageError, match="ego_pose_covariance"):
        observation_from_msg(msg)


HARSH = np.diag([0.30**2, 0.30**2, 0.05**2])  # harsh sensing's localiser: m = 2 (0.30 + 2.5 x 0.05) = 0.85 m


def _decide_at_entrance(paper_lot, keep: bool, covariance=HARSH):
    """The ego's estimate at the paper lot's entrance, where the episodes start (seed 66 of `contested`), nearer the
    wall behind it than the margin: one decision of the shipped planner, spot 14 vacant."""
    from dataclasses import replace

    from test_planner_decision import make_obs
    from unhurried import unhurried

    from avp_collision.localisation import footprint_inside
    from avp_planner.core.decision import EgoPlanner
    from avp_world.geometry import rect_corners

    s = unhurried()
    planner = EgoPlanner(paper_lot, replace(s, collision=replace(s.collision, localisation_keep_start=keep)))
    ego = np.array([21.42, 38.5, -1.57])
    obs = replace(make_obs(paper_lot, ego, vacant=[14]), ego_covariance=covariance)
    m = localisation_margin(covariance, obs.ego_length, obs.ego_width, 2.0)
    corners = rect_corners(ego[None], obs.ego_length, obs.ego_width)[0]
    assert footprint_inside(localised_lot(paper_lot, 0.0 + 1e-9), corners)  # inside L ...
    inside_margin = footprint_inside(localised_lot(paper_lot, m), corners)  # ... and, under harsh noise, not L'
    return planner.decide(obs), inside_margin


def test_the_margin_alone_holds_the_ego_still_at_the_entrance_and_keeping_its_footprint_frees_it(paper_lot):
    still, inside = _decide_at_entrance(paper_lot, keep=False)
    assert not inside
    assert still.mode == "idle" and still.trace.get("cause") == "static", (still.mode, still.trace)
    moves, _ = _decide_at_entrance(paper_lot, keep=True)
    assert moves.mode == "park" and moves.spot_id == 14 and moves.command[0] != 0.0
    # the plan keeps the margin away from the wall once it has left the ego's own footprint
    from shapely.geometry import Polygon
    from test_planner_decision import L, W

    from avp_world.geometry import rect_corners

    m = localisation_margin(HARSH, L, W, 2.0)
    lp = Polygon(localised_lot(paper_lot, m).boundary)
    start = Polygon(rect_corners(moves.poses[:1], L, W)[0]).buffer(0.3)
    spot = Polygon(paper_lot.spot_corners[paper_lot.spot_index(14)])
    for p in moves.poses[::5]:
        fp = Polygon(rect_corners(p[None], L, W)[0])
        assert fp.difference(lp.union(start).union(spot)).area < 1e-3


def test_keeping_the_footprint_changes_nothing_where_the_margin_leaves_the_ego_inside(paper_lot):
    realistic = np.diag([0.15**2, 0.15**2, 0.025**2])
    a, inside = _decide_at_entrance(paper_lot, keep=False, covariance=realistic)
    b, _ = _decide_at_entrance(paper_lot, keep=True, covariance=realistic)
    assert inside and a.mode == b.mode == "park" and np.array_equal(a.poses, b.poses)


def test_the_footprint_is_checked_against_the_margin_once_a_step(paper_lot, monkeypatch):
    """With ``collision.localisation_keep_start`` on, the static world and the spots' world of one decision (a parked
    car outside the believed-occupied spots builds both) ask for the same planning lot: the footprint test runs once,
    and the ego still leaves the entrance for spot 14."""
    from dataclasses import replace

    from test_planner_decision import make_obs, static_car
    from unhurried import unhurried

    import avp_motion.planner_inputs as inputs
    from avp_planner.core.decision import EgoPlanner

    calls = []
    real = inputs.footprint_inside

    def counted(lot, corners):
        calls.append(1)
        return real(lot, corners)

    monkeypatch.setattr(inputs, "footprint_inside", counted)
    s = unhurried()
    planner = EgoPlanner(paper_lot, replace(s, collision=replace(s.collision, localisation_keep_start=True)))
    x, y, th = paper_lot.spot_poses[paper_lot.spot_index(3)]
    obs = replace(make_obs(paper_lot, (21.42, 38.5, -1.57), vacant=[14, 3], vehicles=[static_car(7, x, y, th)]),
                  ego_covariance=HARSH)
    moves = planner.decide(obs)
    assert len(calls) == 1
    assert moves.mode == "park" and moves.spot_id == 14

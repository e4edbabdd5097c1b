"""The §V-D decision logic (park / explore / idle) on hand-built observations, and closed loop in the simulator."""

from __future__ import annotations

import math
from pathlib import Path as FsPath

import numpy as np
import pytest
from shapely import affinity
from shapely.geometry import Polygon, box
from shapely.ops import unary_union
from unhurried import unhurried

from avp_planner.core.decision import EgoPlanner
from avp_world.kinematics import rollout_vehicle
from avp_world.types import Observation, ObservedVehicle, PredictedTrajectory

L, W = 4.6, 1.85
ROOT = FsPath(__file__).resolve().parents[1]


def footprint(x, y, th, length=L, width=W):
    b = box(-length / 2, -width / 2, length / 2, width / 2)
    return affinity.translate(affinity.rotate(b, th, origin=(0, 0), use_radians=True), x, y)


def make_obs(lot, ego, vacant=(), occupied=None, vehicles=(), step=0, speed=0.0):
    if occupied is None:
        occupied = [s.id for s in lot.spots if s.id not in set(vacant)]
    return Observation(step=step, dt=0.1, ego_pose=np.asarray(ego, float), ego_length=L, ego_width=W,
                       ego_speed=speed, vacant_spot_ids=np.asarray(vacant, np.int64),
                       occupied_spot_ids=np.asarray(occupied, np.int64), vehicles=tuple(vehicles))


def static_car(vid, x, y, th, length=L, width=W):
    return ObservedVehicle(id=vid, length=length, width=width, is_static=True, history=np.array([[x, y, th]]))


@pytest.fixture()
def planner(paper_lot):
    return EgoPlanner(paper_lot, unhurried())


def test_beliefs_from_observation_only(paper_lot, planner):
    assert np.all(planner.beliefs == 0.5)
    planner.decide(make_obs(paper_lot, (21.5, 30, -math.pi / 2), vacant=[22], occupied=[21, 23]))
    b = planner.beliefs
    k = paper_lot.spot_index
    assert b[k(22)] == 0.0 and b[k(21)] == 1.0 and b[k(23)] == 1.0 and b[k(5)] == 0.5
    # not observed any more: kept; re-observed: overwritten
    planner.decide(make_obs(paper_lot, (21.5, 30, -math.pi / 2), vacant=[23], occupied=[5]))
    assert b[k(22)] == 0.0 and b[k(23)] == 0.0 and b[k(5)] == 1.0 and b[k(21)] == 1.0


def test_parks_in_an_observed_vacant_spot_and_reaches_it(paper_lot, planner):
    ego = np.array([21.5, 30.0, -math.pi / 2])
    obs = make_obs(paper_lot, ego, vacant=[22])
    d = planner.decide(obs)
    assert d.mode == "park" and d.spot_id == 22 and d.n_candidates == 1
    assert d.command == tuple(d.controls[0])
    states = rollout_vehicle(ego, d.controls, 0.1)
    k = paper_lot.spot_index(22)
    spot = Polygon(paper_lot.spot_corners[k])
    assert footprint(*states[-1]).within(spot)
    occupied = unary_union([Polygon(paper_lot.spot_corners[i]) for i in range(paper_lot.n_spots) if i != k])
    lot_poly = Polygon(paper_lot.boundary)
    for s in states:
        fp = footprint(*s)
        assert fp.within(lot_poly) and not fp.intersects(occupied)
    assert {"spot_selection_time", "path_planning_time", "total"} <= set(d.timings)


def test_time_budget_stops_the_searches(paper_lot):
    """decide(time_budget=...) (the planner node's real-time deadline): with no time left no search starts and
    the ego waits; with enough, the same step parks as without a budget."""
    obs = make_obs(paper_lot, np.array([21.5, 30.0, -math.pi / 2]), vacant=[22])
    starved = EgoPlanner(paper_lot, unhurried()).decide(obs, time_budget=0.0)
    assert starved.mode == "idle" and not starved.stats.get("queries")
    roomy = EgoPlanner(paper_lot, unhurried()).decide(obs, time_budget=5.0)
    free = EgoPlanner(paper_lot, unhurried()).decide(obs)
    assert roomy.mode == free.mode == "park" and roomy.spot_id == free.spot_id == 22
    np.testing.assert_array_equal(roomy.controls, free.controls)


def test_candidate_threshold_delta(paper_lot, planner):
    """Only observed vacant spots with b <= δ are candidates; b > δ makes the planner look elsewhere."""
    ego = (21.5, 30.0, -math.pi / 2)
    b = np.ones(paper_lot.n_spots)
    b[paper_lot.spot_index(22)] = 0.31  # > δ = 0.3
    b[paper_lot.spot_index(24)] = 0.0  # <= δ but not observed vacant now
    d = planner.decide(make_obs(paper_lot, ego, vacant=[22]), beliefs=b)
    assert d.n_candidates == 0 and d.mode != "park"
    b[paper_lot.spot_index(22)] = 0.3
    planner.reset()
    d = planner.decide(make_obs(paper_lot, ego, vacant=[22]), beliefs=b)
    assert d.n_candidates == 1 and d.mode == "park" and d.spot_id == 22


def test_exploration_points_geometry_and_order(paper_lot, planner):
    ego = np.array([21.5, 30.0, -math.pi / 2])
    pts = planner.exploration_points(ego)
    head = np.array([math.cos(ego[2]), math.sin(ego[2])])
    assert len(pts) == 3
    for pose, front, _ in pts:
        assert abs(math.hypot(pose[0] - ego[0], pose[1] - ego[1]) - 11.5) < 1e-9  # on the sensing circle
        assert front == (float(head @ (pose[:2] - ego[:2])) >= 0)
        away = np.array([math.cos(pose[2]), math.sin(pose[2])]) @ (pose[:2] - ego[:2])
        assert away > 0  # heading along the road, away from the ego
    fronts = [f for _, f, _ in pts]
    assert fronts == sorted(fronts, reverse=True)  # front points first
    assert fronts.count(True) == 1  # ahead on the middle road; the top road's crossings lie behind
    assert np.allclose(pts[0][0], [21.5, 18.5, -math.pi / 2])


def test_explores_ahead_first_and_backwards_only_when_blocked(paper_lot, planner):
    ego = (21.5, 30.0, -math.pi / 2)
    d = planner.decide(make_obs(paper_lot, ego))  # nothing vacant: explore
    assert d.mode == "explore" and d.n_candidates == 0
    assert d.goal[1] < 30.0 and abs(d.goal[2] + math.pi / 2) < 1e-9  # ahead, down the middle road
    assert abs(d.goal[0] - (21.5 - 1.75)) < 1e-9  # on the right-hand lane
    # a car across the aisle ahead: the ego must explore backwards (a top-road point behind it)
    planner.reset()
    blocker = static_car(500, 21.5, 22.0, 0.0, length=5.0)
    d = planner.decide(make_obs(paper_lot, ego, vehicles=[blocker]))
    assert d.mode == "explore"
    assert d.goal[1] > 35.0, d.goal  # on the top road
    assert float(np.array([0.0, -1.0]) @ (d.goal[:2] - np.array(ego[:2]))) < 0  # behind the ego


def test_idle_when_boxed_in(paper_lot, planner):
    """Cars across the aisle ahead and behind, every spot occupied: nowhere to go (both exploration points on
    the middle road lie beyond the cars, the other roads are out of sensing range)."""
    ego = (21.5, 20.0, -math.pi / 2)
    ahead = static_car(500, 21.5, 10.0, 0.0, length=5.0)
    behind = static_car(501, 21.5, 29.0, 0.0, length=5.0)
    d = planner.decide(make_obs(paper_lot, ego, vehicles=[ahead, behind]))
    assert d.mode == "idle" and d.command == (0.0, 0.0)
    assert "no safe" in d.reason
    # vacant spot beside the ego: it parks instead of idling
    planner.reset()
    d = planner.decide(make_obs(paper_lot, ego, vacant=[13], vehicles=[ahead, behind]))
    assert d.mode == "park" and d.spot_id == 13


def test_nan_inputs_give_idle_with_a_reason(paper_lot, planner):
    d = planner.decide(make_obs(paper_lot, (np.nan, 30.0, 0.0)))
    assert d.mode == "idle" and d.command == (0.0, 0.0) and "NaN" in d.reason
    b = np.zeros(paper_lot.n_spots)
    b[3] = np.nan
    d = planner.decide(make_obs(paper_lot, (21.5, 30.0, 0.0)), beliefs=b)
    assert d.mode == "idle" and "NaN in beliefs" in d.reason
    bad = PredictedTrajectory(agent_id=7, poses=np.array([[1.0, np.nan, 0.0]]), dt=0.1, length=L, width=W)
    d = planner.decide(make_obs(paper_lot, (21.5, 30.0, 0.0)), predictions=[bad])
    assert d.mode == "idle" and "prediction of agent 7" in d.reason
    d = planner.decide(make_obs(paper_lot, (21.5, 30.0, -math.pi / 2), vacant=[22]))
    assert d.mode == "park"  # recovers on the next valid input


def test_determinism(paper_lot):
    seq = [make_obs(paper_lot, (21.5, 30.0, -math.pi / 2), vacant=[22, 14], step=0)]
    outs = []
    for _ in range(2):
        p = EgoPlanner(paper_lot, unhurried())
        d = p.decide(seq[0])
        outs.append((d.mode, d.spot_id, d.command, d.controls.tobytes(), d.poses.tobytes(), d.cost))
    assert outs[0] == outs[1]


def test_predicted_vehicle_takes_the_best_spot(paper_lot, planner):
    """A vehicle predicted to park in the spot the ego would choose makes it pick another one."""
    ego = (21.5, 24.0, -math.pi / 2)
    obs = make_obs(paper_lot, ego, vacant=[22, 25])
    first = planner.decide(obs)
    assert first.mode == "park"
    target = first.spot_id
    k = paper_lot.spot_index(target)
    sx, sy, sth = paper_lot.spot_poses[k]
    # the other car, already at the spot's mouth, drives into it within 2 s and stays (a prediction holds
    # its last pose)
    n = 20
    c, s = math.cos(sth), math.sin(sth)
    along = np.linspace(-2.0, 0.0, n)
    poses = np.column_stack([sx + along * c, sy + along * s, np.full(n, sth)])
    pred = PredictedTrajectory(agent_id=1001, poses=poses, dt=0.1, length=L, width=W, spot_id=target)
    planner.reset()
    second = planner.decide(obs, predictions=[pred])
    assert second.mode == "park" and second.spot_id != target


def test_replans_when_the_target_spot_turns_out_occupied(paper_lot, planner):
    ego = np.array([21.5, 30.0, -math.pi / 2])
    d = planner.decide(make_obs(paper_lot, ego, vacant=[22, 24]))
    assert d.mode == "park"
    target = d.spot_id
    other = 24 if target == 22 else 22
    # execute a few steps
    pose = ego
    for step in range(1, 4):
        pose = rollout_vehicle(pose, np.array([d.command]), 0.1)[-1]
        d = planner.decide(make_obs(paper_lot, pose, vacant=[22, 24], step=step, speed=d.command[0]))
        assert d.mode == "park" and d.spot_id == target and not d.replanned
    # now the target spot is observed occupied: the rest of the plan is obstructed -> new plan to the other
    occ = [s.id for s in paper_lot.spots if s.id != other]
    d = planner.decide(make_obs(paper_lot, pose, vacant=[other], occupied=occ, step=4, speed=d.command[0]))
    assert d.mode == "park" and d.spot_id == other and d.replanned


# ------------------------------------------------------------------------------------------------ closed loop


def _run_episode(lot, seed, reactive):
    import avp_sim.params
    from avp_common.params import load_yaml_params
    from avp_sim.core.factory import make_world

    p = load_yaml_params(ROOT / "src/avp_sim/config/sim.param.yaml", "avp_sim", avp_sim.params.SIM_PARAMS)
    world = make_world(lot, p, seed, reactive)
    planner = EgoPlanner(lot, unhurried())
    while not world.done:
        d = planner.decide(world.observe(), None, [])
        world.step(*d.command)
    return world


@pytest.mark.parametrize("reactive", [True, False])
def test_closed_loop_in_the_simulator(paper_lot, reactive):
    seeds = [0, 4, 7, 9, 12]
    results = [_run_episode(paper_lot, s, reactive) for s in seeds]
    assert not any(w.metrics.collision for w in results), [w.metrics.collision_with for w in results]
    n_ok = sum(w.metrics.success for w in results)
    assert n_ok >= len(seeds) - 1, [w.status for w in results]
    for w in results:
        if w.metrics.success:
            assert w.metrics.parking_time < 60.0


def test_evasive_when_standing_still_is_hit(paper_lot):
    """A car rushing up the aisle at the ego (and stopping where the ego could go) makes every plan unsafe;
    standing still is hit first, so the ego backs away (the plan that is hit latest) instead of idling. The paper's
    check (``collision.reactive_steps: 0``): with the shipped assumption the car would stop for the ego."""
    from dataclasses import replace

    s = unhurried()
    planner = EgoPlanner(paper_lot, replace(s, collision=replace(s.collision, reactive_steps=0)))
    ego = np.array([21.5, 25.0, -math.pi / 2])
    n = 40
    ys = 12.0 + 0.5 * np.arange(1, n + 1)  # 5 m/s northwards, then holds y = 32
    pred = PredictedTrajectory(agent_id=1, poses=np.column_stack([np.full(n, 21.5), ys, np.full(n, math.pi / 2)]),
                               dt=0.1, length=L, width=W)
    d = planner.decide(make_obs(paper_lot, ego), predictions=[pred])
    assert d.mode != "idle" and d.reason.startswith("evasive"), d.reason
    assert d.command[0] < 0  # reversing, away from the car
    settings = planner.settings
    calm = EgoPlanner(paper_lot, replace(settings, decision=replace(settings.decision, evasive=False)))
    d = calm.decide(make_obs(paper_lot, ego), predictions=[pred])
    assert d.mode == "idle"


def test_parked_cars_inside_occupied_spots_leave_the_static_world_unchanged(paper_lot, planner):
    """The world is built without static vehicles lying inside believed-occupied spots (a speed-up): its raster,
    signed distance field and exact answers equal those of a world built with every vehicle (the oracle), and
    a vehicle sticking out of its spot is kept."""
    from avp_collision.static import StaticWorld

    s21, s22 = paper_lot.spots[paper_lot.spot_index(21)], paper_lot.spots[paper_lot.spot_index(22)]
    inside = static_car(1, s21.x, s21.y, s21.heading)  # a 4.6 x 1.85 car centred in its spot
    out = static_car(2, s22.x + 2.0 * math.cos(s22.heading), s22.y + 2.0 * math.sin(s22.heading), s22.heading)
    obs = make_obs(paper_lot, (21.5, 30, -math.pi / 2), vacant=[], vehicles=(inside, out))
    b = planner.update_beliefs(obs).copy()
    world = planner._static_world(obs, b)
    assert len(world.obstacle_poses) == int((b >= 0.5).sum()) + 1  # the car sticking out is kept
    occ = np.nonzero(b >= 0.5)[0]
    full = StaticWorld(paper_lot, np.r_[paper_lot.spot_poses[occ], [inside.pose, out.pose]],
                       np.r_[paper_lot.spot_dims[occ], [[L, W], [L, W]]], L, W, planner.settings.collision)
    assert np.array_equal(world.grid, full.grid) and np.array_equal(world._sdf_flat, full._sdf_flat)
    rng = np.random.default_rng(0)
    x0, y0, x1, y1 = paper_lot.bounds()
    xs, ys, th = rng.uniform(x0, x1, 4000), rng.uniform(y0, y1, 4000), rng.uniform(-math.pi, math.pi, 4000)
    c, s = np.cos(th), np.sin(th)
    assert np.array_equal(world.free_xyc(xs, ys, c, s, 0.1), full.free_xyc(xs, ys, c, s, 0.1))
    assert np.array_equal(world.exact_free_xyc(xs, ys, c, s, 0.1), full.free_xyc(xs, ys, c, s, 0.1))
    # the cache: the same inputs give the same world; world.key names every input, the contained car included
    key = world.key
    assert planner._static_world(obs, b) is world and world.key == key
    obs2 = make_obs(paper_lot, (21.5, 30, -math.pi / 2), vacant=[], vehicles=(out,))
    assert planner._static_world(obs2, b) is world and world.key != key


def test_idle_replan_steps(paper_lot):
    """decision.idle_replan_steps: after an idle decision the ego stays put without searching until N steps have
    passed (protocols paper/contested: 5, Nawaz's 0.5 s step); 1 searches every step (the default)."""
    from dataclasses import replace

    ego = (21.5, 20.0, -math.pi / 2)
    walls = [static_car(500, 21.5, 10.0, 0.0, length=5.0), static_car(501, 21.5, 29.0, 0.0, length=5.0)]
    every = EgoPlanner(paper_lot, unhurried())
    five = EgoPlanner(paper_lot, replace(unhurried(), decision=replace(unhurried().decision,
                                                                             idle_replan_steps=5)))
    reasons = {1: [], 5: []}
    for k in range(7):
        obs = make_obs(paper_lot, ego, vehicles=walls, step=k)
        reasons[1].append(every.decide(obs).reason)
        d = five.decide(obs)
        assert d.mode == "idle" and d.command == (0.0, 0.0)
        reasons[5].append(d.reason)
    assert all("no safe" in r for r in reasons[1])
    searched = [k for k, r in enumerate(reasons[5]) if "no safe" in r]
    assert searched == [0, 5] and all("idle_replan_steps" in r for k, r in enumerate(reasons[5]) if k not in searched)
    # a spot that frees up is taken at the next re-plan, not before
    five.reset()
    five.decide(make_obs(paper_lot, ego, vehicles=walls, step=0))
    assert five.decide(make_obs(paper_lot, ego, vacant=[13], vehicles=walls, step=1)).mode == "idle"
    assert five.decide(make_obs(paper_lot, ego, vacant=[13], vehicles=walls, step=5)).mode == "park"


def test_searches_are_not_repeated(paper_lot, monkeypatch):
    """The same search in the same scene from the same pose ends the same way: the planner remembers searches
    (SEARCH_CACHE; here spot 0 fails a 3-iteration budget and the exploration points are reached) and does not run
    them again — the decision is unchanged, pose for pose; another scene (spot 5 vacant instead) is searched."""
    from dataclasses import replace

    from avp_search.hybrid_astar import HybridAStar

    ego = (21.5, 30.0, -math.pi / 2)
    s = unhurried()
    p = EgoPlanner(paper_lot, replace(s, search=replace(s.search, max_iterations=3)))
    spot0 = p.spot_goals(paper_lot.spot_index(0)).tobytes()
    searched = []
    real = HybridAStar.plan
    monkeypatch.setattr(HybridAStar, "plan",
                        lambda self, goals, *a, **k: searched.append(goals.tobytes()) or real(self, goals, *a, **k))
    first = p.decide(make_obs(paper_lot, ego, vacant=[0], step=0))
    n_first = len(searched)
    assert searched.count(spot0) == 1 and first.mode == "explore"
    assert [r.success for r in p._searches.values()].count(False) == 1 and n_first >= 2  # spot 0, then exploring
    kept = p.decide(make_obs(paper_lot, ego, vacant=[0], step=1))  # the ego did not move: within the tolerance
    again = p.decide(make_obs(paper_lot, ego, vacant=[0], step=2))  # not where the plan expects: re-plans
    assert (kept.reason, again.reason) == ("exploring", "new exploration plan")
    assert len(searched) == n_first  # nothing searched again: spot 0's failure and the exploration path remembered
    assert again.mode == first.mode and np.array_equal(again.poses, first.poses)
    p.decide(make_obs(paper_lot, ego, vacant=[5], step=20))
    assert p.spot_goals(paper_lot.spot_index(5)).tobytes() in searched

"""Collision checking against agents that stop for the ego (``collision.reactive_steps``,
avp_collision.reactive), with shapely as the independent oracle of the geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import Polygon
from unhurried import unhurried

from avp_collision.dynamic import DynamicObstacles
from avp_world.geometry import rect_corners
from avp_world.types import PredictedTrajectory

L, W = 4.6, 1.85


def _car_north(y0: float = 5.0, speed: float = 2.0, n: int = 120) -> PredictedTrajectory:
    ys = y0 + 0.1 * speed * np.arange(1, n + 1)
    return PredictedTrajectory(agent_id=3, poses=np.column_stack([np.full(n, 21.5), ys, np.full(n, math.pi / 2)]),
                               dt=0.1, length=L, width=W)


def _ego_line(y0: float, speed: float, n: int) -> np.ndarray:
    return np.column_stack([np.full(n, 21.5), y0 + 0.1 * speed * np.arange(n), np.full(n, -math.pi / 2)])


def _gap(a: np.ndarray, b: np.ndarray) -> float:
    return Polygon(rect_corners(a, L, W)).distance(Polygon(rect_corners(b, L, W)))


def test_a_car_stops_short_of_the_standing_ego():
    """Head-on in one lane: the paper's check says standing still is hit (when the car's hypothesis reaches the
    ego); with the agents' reaction it is never hit, for any look-ahead; a plan driving at the car meets it."""
    car = _car_north()
    standing = np.repeat(_ego_line(25.0, 0.0, 1), 80, axis=0)
    paper = DynamicObstacles([car], L, W)
    k_paper = paper.first_collision(standing)
    assert k_paper > 0 and _gap(car.poses[k_paper - 1], standing[0]) <= 0.3 + 1e-9  # shapely agrees
    for steps in (1, 2, 6):
        react = DynamicObstacles([car], L, W, react_steps=steps)
        assert react.first_collision(standing) == -1
        assert len(react.collision_steps(standing)) == 0
    towards = _ego_line(25.0, -2.0, 80)  # the ego drives south at 2 m/s, at the car
    react = DynamicObstacles([car], L, W, react_steps=2)
    k = react.first_collision(towards)
    assert k > 0
    # the car stood still from some step on; where the ego meets it, it is within the margin of the car's pose
    # (shapely), and the car had stopped more than the margin short of where the ego stood one step before
    assert min(_gap(towards[k], q) for q in car.poses[:k]) <= 0.3 + 1e-9
    away = _ego_line(25.0, 2.0, 80)  # the ego drives north, ahead of the car: the car follows, never meets it
    assert DynamicObstacles([car], L, W, react_steps=2).first_collision(away) == -1


def test_an_agent_far_from_the_plan_is_checked_as_before():
    """An agent that never comes within reach of the ego's plan: the same meetings with and without the rule."""
    car = _car_north()
    crossing = np.column_stack([14.5 + 0.2 * np.arange(80), np.full(80, 12.0), np.zeros(80)])  # drives east at y = 12
    paper = DynamicObstacles([car], L, W).collision_steps(crossing)
    react = DynamicObstacles([car], L, W, react_steps=2).collision_steps(crossing)
    assert len(paper)  # the crossing meets the car
    far = np.column_stack([5.0 + 0.2 * np.arange(80), np.full(80, 60.0), np.zeros(80)])
    assert len(DynamicObstacles([car], L, W, react_steps=2).collision_steps(far)) == 0
    assert len(react) <= len(paper)


def test_the_planner_no_longer_flees_a_car_that_will_stop_for_it(paper_lot):
    """The switch changes the decision: a car rushes at the standing ego. The paper's check predicts that standing
    still is hit, and the evasive extra drives the ego away; with the agents' reaction the car stops short of the
    ego, standing is safe, and the ego waits (its plans run into the stopped car)."""
    from dataclasses import replace

    from test_decision_trace import _rushing_car
    from test_planner_decision import make_obs

    from avp_planner.core.decision import EgoPlanner

    car, pred = _rushing_car()
    obs = make_obs(paper_lot, (21.5, 25.0, -math.pi / 2), vehicles=[car])
    s = unhurried()
    s = replace(s, collision=replace(s.collision, reactive_steps=0))  # the paper's check, whatever the default
    paper = EgoPlanner(paper_lot, s).decide(obs, predictions=[pred])
    assert paper.trace["mode"] == "evasive" and paper.command[0] != 0.0
    react = EgoPlanner(paper_lot, replace(s, collision=replace(s.collision, reactive_steps=2,
                                                                reactive_evidence="assumed"))).decide(
        obs, predictions=[pred])
    assert react.trace["mode"] == "idle" and react.command == (0.0, 0.0), react.trace
    assert react.trace["agent_id"] == 7 and react.trace["motion"] == "towards"


def test_every_shipped_planner_profile_validates():
    """The planner profiles of avp_planner/config/profiles (among them `interactive`) load as the node
    will load them: known keys, right types and ranges."""
    from pathlib import Path

    from avp_bringup.swap import validate_profile

    d = Path(__file__).resolve().parents[1] / "src/avp_planner/config/profiles"
    names = sorted(p.stem for p in d.glob("*.yaml"))
    assert {"default", "cautious", "interactive"} <= set(names)
    for p in d.glob("*.yaml"):
        validate_profile(p)


def _reference_meetings(preds, ego, steps, vm=0.3, pm=0.4, overlap=False):
    """The module docstring's recurrence, written out step by step for one agent at a time (no vectorising, no
    windows, no pre-filters): the first meeting time, or -1. Geometry: the same SAT / disc gaps (shapely checks
    those elsewhere). ``overlap``: ``collision.reactive_trigger: overlap`` — the agent brakes only where its next
    poses would overlap the ego, and it meets the ego within the margin only where the ego's own move brought it
    nearer to the agent's pose, or where they overlap."""
    from avp_collision.reactive import disc_gaps, rect_gaps

    n = max(len(ego), max(len(p.poses) for p in preds) + 1)
    ego = np.concatenate([ego, np.repeat(ego[-1:], n - len(ego), axis=0)])
    first = -1
    for p in preds:
        poses = np.asarray(p.poses, float)
        h = len(poses)

        def gap(j, k, p=p, poses=poses, h=h):
            q = poses[min(max(j, 0), h - 1)]
            if p.is_pedestrian:
                return float(disc_gaps(ego[k], q[:2], L / 2, W / 2, np.float64(p.radius)))
            return float(rect_gaps(ego[k], q, L / 2, W / 2, np.float64(p.length / 2), np.float64(p.width / 2)))

        m = pm if p.is_pedestrian else vm
        trigger = 0.0 if overlap else m
        j = -1
        for k in range(1, n):
            brakes = any(gap(j + i, k - 1) <= trigger for i in range(1, steps + 1))
            if not brakes:
                j = min(j + 1, h - 1)
            met = gap(j, k) <= m
            if overlap and 0.0 < gap(j, k) and gap(j, k) >= gap(j, k - 1) - 1e-9:
                met = False  # the agent came nearer, not the ego: it brakes before it would overlap
            if met:
                first = k if first < 0 else min(first, k)
                break
    return first


def test_the_vectorised_roll_out_equals_the_recurrence_written_out():
    """avp_collision.reactive (vectorised over agents, rolled out only where some gap is finite, agents pre-filtered
    by bounding box) against the plain recurrence, on random scenes: the same first meeting."""
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(60):
        preds = []
        for i in range(int(rng.integers(1, 4))):
            n = int(rng.integers(5, 30))
            p0, v = rng.uniform(-8, 8, 2), rng.uniform(-3, 3, 2)
            t = np.arange(1, n + 1) * 0.1
            preds.append(PredictedTrajectory(agent_id=i, poses=np.column_stack(
                [p0[0] + v[0] * t, p0[1] + v[1] * t, np.full(n, math.atan2(v[1], v[0]))]), dt=0.1,
                is_pedestrian=bool(rng.random() < 0.3), length=L, width=W, radius=0.3))
        m = int(rng.integers(2, 40))
        e0, ev = rng.uniform(-4, 4, 2), rng.uniform(-2, 2, 2)
        t = np.arange(m) * 0.1
        ego = np.column_stack([e0[0] + ev[0] * t, e0[1] + ev[1] * t, np.full(m, math.atan2(ev[1], ev[0]))])
        steps = int(rng.integers(1, 5))
        for trigger in ("margin", "overlap"):
            dyn = DynamicObstacles(preds, L, W, keep_current_gap=False, react_steps=steps, react_trigger=trigger)
            ref = _reference_meetings(preds, ego, steps, overlap=trigger == "overlap")
            assert dyn.first_collision(ego) == ref, trigger
            checked += ref > 0
    assert checked >= 20  # enough scenes where an agent is met


def _plain_roll_out(g, margin, react, steps, own_n, hold_last, k0, first_only, ego_closes):
    """The recurrence over a gap table G[a, j, k], one agent and one step at a time, every step from 1."""
    a_n, h, n = g.shape
    out = []
    for a in range(a_n):
        j = -1
        for k in range(1, n):
            if not any(g[a, min(j + i, h - 1), k - 1] <= react[a] for i in range(1, steps + 1)):
                j = min(j + 1, h - 1)
            now = g[a, max(j, 0), k]
            met = k >= k0 and now <= margin[a]
            if met and ego_closes and np.isfinite(react[a]):
                met = now <= 0.0 or now < g[a, max(j, 0), k - 1] - 1e-9
            if met and not hold_last:
                met = j < own_n[a]
            if met:
                out.append((k, a))
    out.sort()
    if first_only and out:
        out = [(k, a) for k, a in out if k == out[0][0]]
    return [k for k, _ in out], [a for _, a in out]


def test_the_roll_out_over_a_gap_table_equals_the_plain_recurrence():
    """avp_collision.reactive._roll_out (tables of both tests, j stepped through bytes, only the steps where some gap
    is finite) against the recurrence written out, on random gap tables with unreachable pairs (+inf), agents the
    rule leaves out (-inf), and every switch: the same meetings in the same order."""
    from avp_collision.reactive import _roll_out

    rng = np.random.default_rng(11)
    met = 0
    for _ in range(150):
        a_n, h, n = int(rng.integers(1, 5)), int(rng.integers(1, 12)), int(rng.integers(2, 30))
        g = rng.uniform(-0.5, 3.0, (a_n, h, n))
        if rng.random() < 0.5:
            g = np.round(g * 4.0) / 4.0  # ties with the margin and the reaction distance
        g[rng.random(g.shape) < 0.5] = np.inf
        if rng.random() < 0.3:
            g[:, :, : int(rng.integers(0, n))] = np.inf  # the plan reaches the agents late
        margin = np.round(rng.uniform(0.2, 0.6, a_n) * 4.0) / 4.0
        react = np.where(rng.random(a_n) < 0.25, -np.inf, margin + np.round(rng.uniform(0.0, 0.8, a_n) * 4.0) / 4.0)
        own_n = rng.integers(0, h + 1, a_n)
        steps, k0 = int(rng.integers(1, 4)), int(rng.integers(0, 6))
        for hold_last in (True, False):
            for first_only in (True, False):
                for ego_closes in (True, False):
                    args = (g, margin, react, steps, own_n, hold_last, k0, first_only, ego_closes)
                    k, a = _roll_out(*args)
                    assert k.dtype == a.dtype == np.int64
                    assert (list(k), list(a)) == _plain_roll_out(*args), args[3:]
                    met += len(k) > 0
    assert met >= 300  # most tables have meetings


def test_the_plan_poses_are_made_distinct_as_numpy_does():
    """avp_collision.reactive._unique_rows against np.unique(axis=0, return_inverse=True) on plans with repeated poses
    (an ego that waits): the same rows in the same order and the same inverse, bit for bit where no -0.0 is in play
    (where one is, 0.0 and -0.0 are one row, as in numpy, and equal by value)."""
    from avp_collision.reactive import _unique_rows

    rng = np.random.default_rng(5)
    exact = 0
    for _ in range(400):
        r = int(rng.integers(1, 80))
        x = np.round(rng.normal(0.0, 10.0, (r, 3)), int(rng.integers(0, 3)))
        x = x[rng.integers(0, r, int(rng.integers(1, 3 * r)))]  # waits: poses repeated, out of order too
        u, inv = np.unique(x, axis=0, return_inverse=True)
        u2, inv2 = _unique_rows(x)
        assert np.array_equal(u, u2) and np.array_equal(inv.reshape(-1), inv2) and inv2.dtype == np.intp
        assert np.array_equal(u2[inv2], x)
        if not np.any(np.signbit(x) & (x == 0.0)):
            assert u.tobytes() == u2.tobytes()
            exact += 1
    assert exact >= 100


def _stopping_car(speeds: list[float], y_end: float = 16.0, vid: int = 7):
    """A car driving north up the middle aisle at the given speeds (m/s, one per 0.1 s step, the last = now),
    ending at y = ``y_end``, and its prediction: it drives on north at 5 m/s."""
    from avp_world.types import ObservedVehicle

    ys = y_end - 0.1 * np.concatenate([np.cumsum(np.asarray(speeds, float)[::-1])[::-1], [0.0]])
    hist = np.column_stack([np.full(len(ys), 21.5), ys, np.full(len(ys), math.pi / 2)])
    n = 40
    ys_pred = y_end + 0.5 * np.arange(1, n + 1)
    poses = np.column_stack([np.full(n, 21.5), ys_pred, np.full(n, math.pi / 2)])
    pred = PredictedTrajectory(agent_id=vid, poses=poses, dt=0.1, length=L, width=W, probability=0.75)
    return ObservedVehicle(id=vid, length=L, width=W, is_static=False, history=hist), pred


def test_evidence_is_a_hard_stop_with_the_ego_ahead(paper_lot):
    """``collision.reactive_evidence``'s test (avp_motion.yielding.ReactionEvidence): a car that stops at once
    with the ego 9 m ahead is seen to react; one that slows as a planned stop does (1.5 m/s², ParkSim's), one that
    stops with the ego behind it, or one that stops with the ego beyond the look-ahead, is not. A pedestrian is
    judged on the speed remembered from the step before."""
    from test_planner_decision import make_obs

    from avp_motion.yielding import ReactionEvidence
    from avp_world.types import ObservedPedestrian

    ego = (21.5, 25.0, -math.pi / 2)
    hard, _ = _stopping_car([2.0, 2.0, 2.0, 0.0], vid=1)
    gentle, _ = _stopping_car([0.6, 0.45, 0.3, 0.15], vid=2)
    ev = ReactionEvidence(lookahead=10.0, decel=3.0)
    crawl, _ = _stopping_car([1.1, 1.1, 1.1, 0.5], vid=3)  # a manoeuvre's slow-down: hard, but not to a stop
    assert ev.update(make_obs(paper_lot, ego, vehicles=[hard, gentle, crawl])) == {(False, 1)}
    for pose in ((21.5, 10.0, 0.0), (21.5, 28.0, 0.0)):  # behind it; 12 m ahead
        assert ReactionEvidence(10.0, 3.0).update(make_obs(paper_lot, pose, vehicles=[hard])) == set()
    # the threshold is what tells them apart: at 0.5 m/s² the planned stop counts too
    assert ReactionEvidence(10.0, 0.5).update(make_obs(paper_lot, ego, vehicles=[gentle])) == {(False, 2)}
    ev = ReactionEvidence(10.0, 3.0)
    walk = ObservedPedestrian(id=4, radius=0.3, position=np.array([21.5, 20.0]),
                              previous_position=np.array([21.5, 19.88]))
    stop = ObservedPedestrian(id=4, radius=0.3, position=np.array([21.5, 20.0]),
                              previous_position=np.array([21.5, 20.0]))
    ev.update(replace_peds(make_obs(paper_lot, ego), [walk], 0))
    assert ev.update(replace_peds(make_obs(paper_lot, ego), [stop], 1)) == {(True, 4)}
    ev2 = ReactionEvidence(10.0, 3.0)  # a step missed in between: no evidence
    ev2.update(replace_peds(make_obs(paper_lot, ego), [walk], 0))
    assert ev2.update(replace_peds(make_obs(paper_lot, ego), [stop], 2)) == set()


def replace_peds(obs, peds, step):
    from dataclasses import replace

    return replace(obs, pedestrians=tuple(peds), step=step)


def test_the_evidence_switch_changes_the_decision(paper_lot):
    """With ``reactive_evidence: agent`` a car is assumed to stop for the ego only once it has been seen to: while
    it drives at the ego the planner flees it as the paper's check does; once it has stopped hard in front of the
    ego (and is still predicted to drive on), the ego waits for it as under ``assumed``. With ``lot``, another car
    seen stopping is enough."""
    from dataclasses import replace

    from test_planner_decision import make_obs

    from avp_planner.core.decision import EgoPlanner

    ego = (21.5, 25.0, -math.pi / 2)
    s = unhurried()
    s = replace(s, collision=replace(s.collision, reactive_steps=0))  # the paper's check, whatever the default

    def planner(evidence: str) -> EgoPlanner:
        return EgoPlanner(paper_lot, replace(s, collision=replace(s.collision, reactive_steps=2,
                                                                   reactive_evidence=evidence)))

    moving, pred = _stopping_car([5.0] * 6)
    stopped, pred_stopped = _stopping_car([5.0] * 5 + [0.0])
    assert planner("agent").decide(make_obs(paper_lot, ego, vehicles=[moving]), predictions=[pred]).trace["mode"] \
        == "evasive"
    assert planner("assumed").decide(make_obs(paper_lot, ego, vehicles=[moving]),
                                     predictions=[pred]).trace["mode"] == "idle"
    p = planner("agent")
    d = p.decide(make_obs(paper_lot, ego, vehicles=[stopped]), predictions=[pred_stopped])
    assert d.trace["mode"] == "idle" and d.command == (0.0, 0.0), d.trace
    assert p._evidence.seen == {(False, 7)}
    # the paper's check, on the same scene: the car's hypothesis still drives through the ego
    assert EgoPlanner(paper_lot, s).decide(make_obs(paper_lot, ego, vehicles=[stopped]),
                                           predictions=[pred_stopped]).trace["mode"] == "evasive"
    # lot: another car (9) seen stopping for the ego makes car 7 reactive too; agent: it does not
    for evidence, mode in (("lot", "idle"), ("agent", "evasive")):
        p = planner(evidence)
        p._evidence.seen.add((False, 9))
        d = p.decide(make_obs(paper_lot, ego, vehicles=[moving]), predictions=[pred])
        assert d.trace["mode"] == mode, (evidence, d.trace)


def test_told_reactions_change_the_decision_and_nothing_else(paper_lot):
    """``reactive_evidence: told`` (the oracle bound's: ground truth names the agents that react): a car told to
    react is assumed to stop for the ego, so the ego no longer flees it; told nothing, or told of another agent, the
    check is the paper's; what the car does in front of the ego (stopping hard) is not evidence under ``told``."""
    from dataclasses import replace

    from test_planner_decision import make_obs

    from avp_planner.core.decision import EgoPlanner

    ego = (21.5, 25.0, -math.pi / 2)
    s = unhurried()
    s = replace(s, collision=replace(s.collision, reactive_steps=2, reactive_evidence="told"))
    moving, pred = _stopping_car([5.0] * 6)
    stopped, pred_stopped = _stopping_car([5.0] * 5 + [0.0])
    p = EgoPlanner(paper_lot, s)
    assert p.decide(make_obs(paper_lot, ego, vehicles=[moving]), predictions=[pred]).trace["mode"] == "evasive"
    p.tell_reacting({(True, 7), (False, 9)})  # a pedestrian 7 and car 9 react; car 7 does not
    assert p.decide(make_obs(paper_lot, ego, vehicles=[moving]), predictions=[pred]).trace["mode"] == "evasive"
    assert p.decide(make_obs(paper_lot, ego, vehicles=[stopped]),
                    predictions=[pred_stopped]).trace["mode"] == "evasive"  # a hard stop is no evidence here
    p.tell_reacting([(False, 7)])
    d = p.decide(make_obs(paper_lot, ego, vehicles=[moving]), predictions=[pred])
    assert d.trace["mode"] == "idle" and d.command == (0.0, 0.0), d.trace
    p.reset()  # a new episode forgets what it was told
    assert p.decide(make_obs(paper_lot, ego, vehicles=[moving]), predictions=[pred]).trace["mode"] == "evasive"


@pytest.mark.slow
def test_the_oracle_is_told_which_agents_react():
    """avp_episode.oracle.ground_truth names every dynamic vehicle and pedestrian with n_pass > 0 in the
    reactive mode, and none in the non-reactive mode (the simulator's passiveness read independently here)."""
    from pathlib import Path

    import avp_sim.params
    from avp_common.params import load_yaml_params
    from avp_episode.oracle import ground_truth
    from avp_sim.core.factory import load_lot_param, make_world

    root = Path(__file__).resolve().parents[1] / "src"
    p = load_yaml_params(root / "avp_sim/config/sim.param.yaml", "avp_sim", avp_sim.params.SIM_PARAMS)
    p["scenario.family"] = "busy"  # cars and pedestrians
    lot = load_lot_param(str(root / "avp_world/avp_world/maps/dlp_lot.yaml"))
    for reactive in (True, False):
        world = make_world(lot, p, 3, reactive)
        truth = ground_truth(world, 2.0)
        sc = world.scenario
        want = {(False, int(v.id)) for v in sc.vehicles if not v.parked and v.passiveness > 0}
        want |= {(True, int(q.id)) for q in sc.pedestrians if q.passiveness > 0}
        assert truth.reacting == frozenset(want)
        assert bool(want) == reactive and (not reactive or any(k[0] for k in want))


def test_the_overlap_trigger_does_not_trust_a_car_passing_alongside():
    """``collision.reactive_trigger`` (seed 184 of the busy lot in miniature): a car drives north in the
    next lane, 0.2 m from the ego's side, while the ego's plan slides into that lane at 0.3 m/s. With the ``margin``
    trigger the car is assumed to brake as soon as its next poses come within the margin, so the plan is cleared;
    the simulator's car brakes only where it would overlap the ego (§III-B "meets"), and with the ``overlap``
    trigger the plan meets the car, as the paper's check does (a step later at most). Head-on, both triggers still
    let the ego stand (the car stops short of it), and driving at the car still meets it."""
    n = 60
    t = np.arange(1, n + 1) * 0.1
    car = PredictedTrajectory(agent_id=3, poses=np.column_stack([np.full(n, W + 0.2), -6.0 + 2.0 * t,
                                                                 np.full(n, math.pi / 2)]), dt=0.1, length=L, width=W)
    k = np.arange(40)
    slide = np.column_stack([0.03 * k, np.zeros(40), np.full(40, math.pi / 2)])
    paper = DynamicObstacles([car], L, W).first_collision(slide)
    assert paper > 0
    # shapely: the car's hypothesis pose at the meeting is within the margin of the ego's pose there
    assert _gap(car.poses[paper - 1], slide[paper]) <= 0.3 + 1e-9
    assert DynamicObstacles([car], L, W, react_steps=2, react_trigger="margin").first_collision(slide) == -1
    k = DynamicObstacles([car], L, W, react_steps=2, react_trigger="overlap").first_collision(slide)
    assert paper <= k <= paper + 1  # the car drove on: met where the ego, sliding, closes within the margin
    assert _gap(car.poses[k - 1], slide[k]) < _gap(car.poses[k - 1], slide[k - 1]) <= 0.3 + 1e-9  # shapely
    head_on = _car_north()
    standing = np.repeat(_ego_line(25.0, 0.0, 1), 80, axis=0)
    for trigger in ("margin", "overlap"):
        react = DynamicObstacles([head_on], L, W, react_steps=2, react_trigger=trigger)
        assert react.first_collision(standing) == -1, trigger
        assert react.first_collision(_ego_line(25.0, -2.0, 80)) > 0, trigger  # driving at it still meets it

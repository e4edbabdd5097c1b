"""Why the ego is not moving — the planner's decision trace on hand-built scenes (the cause an
oracle can tell: the only car that can block, the only obstacle), its per-episode counts, and ``avp why``."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from test_planner_decision import L, W, make_obs, static_car
from unhurried import unhurried

from avp_motion.trace import DecisionTrace, agent_motion, cause_key
from avp_planner.core.decision import EgoPlanner
from avp_world.types import ObservedVehicle, PredictedTrajectory


def _rushing_car(speed: float = 5.0):
    """A car coming up the middle aisle at the ego (heading north) and its prediction: on the ego's road."""
    n = 40
    ys = 12.0 + 0.1 * speed * np.arange(1, n + 1)
    pred = PredictedTrajectory(agent_id=7, poses=np.column_stack([np.full(n, 21.5), ys, np.full(n, math.pi / 2)]),
                               dt=0.1, length=L, width=W, probability=0.75)
    hist = np.column_stack([np.full(6, 21.5), 12.0 - 0.1 * speed * np.arange(5, -1, -1), np.full(6, math.pi / 2)])
    return ObservedVehicle(id=7, length=L, width=W, is_static=False, history=hist), pred


def test_an_idle_step_names_the_agent_that_blocks_it(paper_lot):
    s = unhurried()
    s = replace(s, collision=replace(s.collision, reactive_steps=0))  # the paper's check: no car assumed to stop
    calm = EgoPlanner(paper_lot, replace(s, decision=replace(s.decision, evasive=False)))
    car, pred = _rushing_car()
    d = calm.decide(make_obs(paper_lot, (21.5, 25.0, -math.pi / 2), vehicles=[car]), predictions=[pred])
    assert d.mode == "idle" and d.command == (0.0, 0.0)
    t = d.trace
    assert t["mode"] == "idle" and t["cause"] == "agent" and t["agent_id"] == 7 and not t["pedestrian"]
    assert t["probability"] == pytest.approx(0.75) and t["hit_step"] >= 1
    assert t["motion"] == "towards" and cause_key(t) == "vehicle:towards"
    # with evasive on (the default), the same scene is an evasive step, not an idle one
    d = EgoPlanner(paper_lot, s).decide(make_obs(paper_lot, (21.5, 25.0, -math.pi / 2), vehicles=[car]),
                                        predictions=[pred])
    assert d.trace["mode"] == "evasive" and d.command[0] != 0.0


def test_evasive_horizon_evades_only_an_imminent_hit(paper_lot):
    """``decision.evasive_horizon``: the standing ego is predicted to be hit at step k (read from the
    planner's own check); a horizon shorter than k·dt leaves it standing (idle, the car named), one at least as long
    evades, as 0 (the shipped value: any predicted hit) does."""
    from avp_collision.dynamic import DynamicObstacles

    car, pred = _rushing_car()
    ego = (21.5, 25.0, -math.pi / 2)
    s = unhurried()
    s = replace(s, collision=replace(s.collision, reactive_steps=0))  # the paper's check, whatever the default
    hit = DynamicObstacles([pred], L, W).first_collision(np.repeat(np.array([ego]), 45, axis=0))
    assert 5 < hit < 40  # the car meets the standing ego later than half a second from now
    t_hit = hit * s.control.dt

    def mode(horizon: float) -> dict:
        p = EgoPlanner(paper_lot, replace(s, decision=replace(s.decision, evasive_horizon=horizon)))
        return p.decide(make_obs(paper_lot, ego, vehicles=[car]), predictions=[pred]).trace

    assert mode(t_hit - 0.3)["mode"] == "idle" and mode(t_hit - 0.3)["agent_id"] == 7
    assert mode(t_hit + 0.05)["mode"] == "evasive"
    assert mode(0.0)["mode"] == "evasive"
    with pytest.raises(ValueError, match="evasive_horizon"):
        replace(s, decision=replace(s.decision, evasive_horizon=-1.0)).validate()


def test_an_idle_step_without_agents_is_static_or_has_no_candidate(paper_lot):
    ego = (21.5, 20.0, -math.pi / 2)
    boxed = [static_car(500, 21.5, 10.0, 0.0, length=5.0), static_car(501, 21.5, 29.0, 0.0, length=5.0)]
    d = EgoPlanner(paper_lot, unhurried()).decide(make_obs(paper_lot, ego, vehicles=boxed))
    # every spot occupied, both exploration goals on the middle road beyond the cars: nothing to search
    assert d.mode == "idle" and d.trace == {"mode": "idle", "cause": "no_candidate"}, d.trace
    # a vacant spot, but a search too short to reach it (and the exploration goals): searched, no path
    s = unhurried()
    short = EgoPlanner(paper_lot, replace(s, search=replace(s.search, max_iterations=3)))
    d = short.decide(make_obs(paper_lot, ego, vacant=[3], vehicles=boxed))
    assert d.mode == "idle" and d.trace == {"mode": "idle", "cause": "static"}, d.trace
    bad = EgoPlanner(paper_lot, unhurried()).decide(make_obs(paper_lot, (np.nan, 30.0, 0.0)))
    assert bad.trace == {"mode": "idle", "cause": "invalid_input"}
    p = EgoPlanner(paper_lot, unhurried())
    d = p.decide(make_obs(paper_lot, (21.5, 30.0, -math.pi / 2), vacant=[22]))
    assert d.trace == {"mode": "park"} and d.command[0] != 0.0


def test_agent_motion_is_read_from_the_observed_history(paper_lot):
    ego = (21.5, 25.0, -math.pi / 2)

    def motion(hist_y):
        y = np.asarray(hist_y, float)
        v = ObservedVehicle(id=3, length=L, width=W, is_static=False,
                            history=np.column_stack([np.full(len(y), 21.5), y, np.full(len(y), math.pi / 2)]))
        return agent_motion(make_obs(paper_lot, ego, vehicles=[v]), 3, False)

    assert motion([10.0] * 7) == "standing"
    assert motion(10.0 + 0.3 * np.arange(7)) == "towards"  # 3 m/s northwards, the ego is north of it
    assert motion(10.0 - 0.3 * np.arange(7)) == "away"
    assert motion(np.r_[10.0 + 0.3 * np.arange(5), 11.2 + 0.05, 11.25 + 0.05]) == "braking"  # 3 -> 0.5 m/s
    assert agent_motion(make_obs(paper_lot, ego), 3, False) == "unseen"


def test_the_trace_counts_modes_causes_and_spells():
    tr = DecisionTrace(0.1)

    def step(k, mode, v, **cause):
        return tr.add(k, SimpleNamespace(mode=mode, command=(v, 0.0), trace={"mode": mode, **cause}))

    for k in range(5):
        step(k, "explore", 1.0)
    lens = [step(k, "idle", 0.0, cause="agent", agent_id=9, pedestrian=False, motion="standing") for k in range(5, 9)]
    assert lens == [1, 2, 3, 4]
    step(9, "wait_and_go", 0.0, cause="agent", agent_id=4, pedestrian=True, motion="towards")
    step(10, "park", 1.0)
    step(11, "idle", 0.0, cause="static")
    step(12, "parked", 0.0)
    s = tr.summary()
    assert s["steps_by_mode"] == {"explore": 5, "idle": 5, "park": 1, "parked": 1, "wait_and_go": 1}
    assert s["idle_steps_by_cause"] == {"pedestrian:towards": 1, "static": 1, "vehicle:standing": 4}
    assert s["longest_idle_steps"] == 5
    assert s["idle_spells"][0] == {"start_step": 5, "steps": 5, "start_s": 0.5, "seconds": 0.5,
                                   "cause": "vehicle:standing", "cause_share": 0.8, "blocking_agents": [9, 4]}
    assert s["idle_spells"][1]["cause"] == "static" and len(s["idle_spells"]) == 2


def test_avp_why_prints_the_spells_of_a_run_record(tmp_path):
    tr = DecisionTrace(0.1)
    for k in range(30):
        tr.add_step(k, "idle", "vehicle:braking", 1003)
    rec = {"method": "bezier", "seed": 5, "mode": "reactive", "decision_trace": tr.summary()}
    (tmp_path / "episodes.jsonl").write_text(json.dumps(rec) + "\n" + json.dumps({**rec, "seed": 6}) + "\n")
    r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "why", str(tmp_path), "--seed", "5"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert "longest idle spell: 30 steps (3.0 s)" in r.stdout
    assert "t =    0.0 s for   3.0 s: vehicle:braking (100 % of its steps); blocking agent(s) [1003]" in r.stdout
    r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "why", str(tmp_path), "--seed", "9"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "no episode of method 'bezier', seed 9" in r.stderr
    records = tmp_path / "arm.jsonl"  # a file of records, as tools/run_seeds.py writes
    records.write_text((tmp_path / "episodes.jsonl").read_text())
    r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "why", str(records), "--seed", "6"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert f"{records}: bezier seed 6 reactive" in r.stdout and "blocking agent(s) [1003]" in r.stdout


# --------------------------------------------------------------------------- the mechanisms against freezing


def _standing_car_and_its_moving_hypothesis(y0: float = 13.0, probability: float = 1.0):
    """A car standing in the middle aisle south of the ego, facing it (history: 0.6 s at rest), predicted to
    drive north at 2 m/s — through the ego's parking manoeuvre into spot 14."""
    hist = np.tile([21.5, y0, math.pi / 2], (7, 1))
    car = ObservedVehicle(id=8, length=L, width=W, is_static=False, history=hist)
    n = 60
    poses = np.column_stack([np.full(n, 21.5), y0 + 0.2 * np.arange(1, n + 1), np.full(n, math.pi / 2)])
    return car, PredictedTrajectory(agent_id=8, poses=poses, dt=0.1, length=L, width=W, probability=probability)


def _planner(lot, **kw):
    """The planner with ``evasive`` and the agents' reaction (``collision.reactive_steps``) off unless given: the
    mechanisms are tested against the paper's check."""

    s = unhurried()  # no wall-clock caps: a loaded machine must not change a decision
    dec = {k: v for k, v in kw.items() if hasattr(s.decision, k)}
    col = {"reactive_steps": 0, **{k: v for k, v in kw.items() if hasattr(s.collision, k)}}
    return EgoPlanner(lot, replace(s, decision=replace(s.decision, evasive=False, **dec),
                                   collision=replace(s.collision, **col)))


def test_assume_yielding_lets_the_ego_go_when_the_car_waits_for_it(paper_lot):
    """Mechanism a: the car stands with the ego 9.7 m ahead of its front; the paper's planner waits for its
    moving hypothesis, the yielding assumption predicts it keeps standing and the ego parks."""
    car, pred = _standing_car_and_its_moving_hypothesis()
    obs = make_obs(paper_lot, (21.5, 25.0, -math.pi / 2), vacant=[14], vehicles=[car])
    paper = _planner(paper_lot).decide(obs, predictions=[pred])
    assert paper.command[0] == 0.0 and paper.trace.get("agent_id") == 8, paper.trace
    assert paper.trace["motion"] == "standing"
    yielding = _planner(paper_lot, assume_yielding=True).decide(obs, predictions=[pred])
    assert yielding.mode == "park" and yielding.spot_id == 14 and yielding.command[0] != 0.0
    # a car beyond the look-ahead (or moving) keeps its hypotheses: the switch changes nothing there
    far, far_pred = _standing_car_and_its_moving_hypothesis(y0=11.0)
    obs_far = make_obs(paper_lot, (21.5, 25.0, -math.pi / 2), vacant=[14], vehicles=[far])
    d = _planner(paper_lot, assume_yielding=True, yield_lookahead=5.0).decide(obs_far, predictions=[far_pred])
    assert d.command[0] == 0.0 and d.trace.get("agent_id") == 8


def test_commit_window_lets_an_improbable_late_conflict_pass(paper_lot):
    """Mechanism b: a hypothesis of probability 0.2 that meets the plan only after the commit window no longer
    blocks it (risk 0.2 <= 0.5); one of probability 0.8 still does; without the window both block."""
    car, pred = _standing_car_and_its_moving_hypothesis(probability=0.2)
    obs = make_obs(paper_lot, (21.5, 25.0, -math.pi / 2), vacant=[14], vehicles=[car])
    paper = _planner(paper_lot).decide(obs, predictions=[pred])
    assert paper.command[0] == 0.0 and paper.trace["hit_step"] > 10, paper.trace
    split = _planner(paper_lot, commit_horizon=1.0, risk_bound=0.5)
    d = split.decide(obs, predictions=[pred])
    assert d.mode == "park" and d.spot_id == 14 and d.command[0] != 0.0
    likely = replace(pred, probability=0.8)
    d = _planner(paper_lot, commit_horizon=1.0, risk_bound=0.5).decide(obs, predictions=[likely])
    assert d.command[0] == 0.0 and d.trace.get("agent_id") == 8


def test_deadlock_breaker_creeps_after_standing_stuck_time(paper_lot):
    """Mechanism d: blocked by a conflict 3 s ahead, the paper's planner stands for ever; the breaker stands
    stuck_time (3 s = 30 steps), then creeps (at most creep_speed) while the next 2 s stay clear, and stops again
    when they do not (the same hypothesis, made to arrive within the check window)."""
    car, pred = _standing_car_and_its_moving_hypothesis()

    def run(planner, prediction, steps=40):
        out = []
        for k in range(steps):
            obs = replace(make_obs(paper_lot, (21.5, 25.0, -math.pi / 2), vacant=[14], vehicles=[car]), step=k)
            out.append(planner.decide(obs, predictions=[prediction]))
        return out

    paper = run(_planner(paper_lot), pred)
    assert all(d.command[0] == 0.0 for d in paper)
    breaker = run(_planner(paper_lot, deadlock_breaker=True), pred)
    first = next(k for k, d in enumerate(breaker) if d.command[0] != 0.0)
    assert first == 30 and breaker[first].trace["mode"] == "creep", (first, breaker[first].trace)
    assert all(0.0 < abs(d.command[0]) <= 0.5 + 1e-9 for d in breaker[first:])
    # the same car predicted to arrive within 1 s: the creep's check fails, the ego keeps standing
    fast = replace(pred, poses=np.column_stack([np.full(60, 21.5), 13.0 + 0.6 * np.arange(1, 61),
                                                 np.full(60, math.pi / 2)]))
    assert all(d.command[0] == 0.0 for d in run(_planner(paper_lot, deadlock_breaker=True), fast))


def test_commit_window_hold_keeps_a_likely_late_conflict_where_the_window_ends(paper_lot):
    """Mechanism b, ``beyond_commit: hold``: a certain hypothesis (probability 1) that meets the plan only after the
    1 s window is cut there and held (the car is assumed to stop for the ego, §III-B): the ego parks, where the risk
    bound (1 > 0.5) and the paper's rule keep it standing; the same car predicted to arrive within the window still
    blocks, and one held in the ego's way at the window's end is still an obstacle."""
    car, pred = _standing_car_and_its_moving_hypothesis(y0=7.0, probability=1.0)  # held at y = 9 after 1 s
    obs = make_obs(paper_lot, (21.5, 25.0, -math.pi / 2), vacant=[14], vehicles=[car])
    assert _planner(paper_lot).decide(obs, predictions=[pred]).command[0] == 0.0
    risk = _planner(paper_lot, commit_horizon=1.0, risk_bound=0.5).decide(obs, predictions=[pred])
    assert risk.command[0] == 0.0 and risk.trace.get("agent_id") == 8, risk.trace
    hold = _planner(paper_lot, commit_horizon=1.0, beyond_commit="hold").decide(obs, predictions=[pred])
    assert hold.mode == "park" and hold.spot_id == 14 and hold.command[0] != 0.0, hold.trace
    fast = replace(pred, poses=np.column_stack([np.full(60, 21.5), 13.0 + 0.8 * np.arange(1, 61),
                                                 np.full(60, math.pi / 2)]))
    d = _planner(paper_lot, commit_horizon=1.0, beyond_commit="hold").decide(obs, predictions=[fast])
    assert d.command[0] == 0.0 and d.trace.get("agent_id") == 8, d.trace



def test_wait_anywhere_stops_on_the_way_for_a_slow_walker(paper_lot):
    """Mechanism c: a pedestrian crosses the aisle 11 m ahead of the ego slowly (0.6 m/s from t = 1 s). Starting
    later by up to max_wait (3 s) still meets them, so the paper's planner idles; with ``wait_anywhere`` the ego
    drives on, stops short of the crossing, waits there (the trace says wait_and_go while it stands) and goes on
    after the walker — a plan whose every pose keeps the pedestrian margin (shapely)."""
    from shapely.geometry import Point, Polygon

    from avp_world.geometry import rect_corners

    n = 100
    t = np.arange(1, n + 1) * 0.1
    x = np.where(t < 1.0, 17.0, 17.0 + 0.6 * (t - 1.0))
    walker = PredictedTrajectory(agent_id=5, poses=np.column_stack([x, np.full(n, 14.0), np.zeros(n)]), dt=0.1,
                                 is_pedestrian=True, radius=0.3)
    obs = make_obs(paper_lot, (21.5, 25.0, -math.pi / 2), vacant=[])
    paper = _planner(paper_lot).decide(obs, predictions=[walker])
    assert paper.mode == "idle" and paper.trace.get("agent_id") == 5, paper.trace
    planner = _planner(paper_lot, wait_anywhere=True)
    d = planner.decide(obs, predictions=[walker])
    assert d.mode == "explore" and d.command[0] != 0.0, d.trace
    plan = planner._plan
    assert plan.wait_from > 10 and plan.wait_steps > 0
    stand = plan.traj.controls[plan.wait_from: plan.wait_from + plan.wait_steps]
    assert np.all(stand == 0.0) and np.all(plan.traj.controls[: plan.wait_from - 1, 0] != 0.0)
    for k, q in enumerate(plan.traj.states[1:], start=1):  # pose k against the walker at t + k dt
        p = walker.poses[min(k - 1, n - 1)]
        assert Polygon(rect_corners(q, L, W)).distance(Point(p[0], p[1])) - 0.3 > 0.4 - 1e-6, k
    traces = []
    for k in range(1, plan.wait_from + 2):
        traces.append(planner.decide(replace(obs, step=k, ego_pose=tuple(plan.traj.states[k])),
                                     predictions=[_shift(walker, k)]).trace["mode"])
    assert traces[-1] == "wait_and_go" and traces[0] == "explore", traces


def _shift(p: PredictedTrajectory, k: int) -> PredictedTrajectory:
    """The same prediction made k steps later (its first k poses gone, the last held)."""
    poses = np.concatenate([p.poses[k:], np.repeat(p.poses[-1:], k, axis=0)])
    return replace(p, poses=poses)


def test_make_way_steps_out_of_the_way_of_a_car_that_waits_for_the_ego(paper_lot):
    """Mechanism e: a car that drove north stands head-on 1.4 m in front of the ego (it waits for the ego, as §III-B's
    agents do; its Bézier hypothesis stands too, at speed 0). The paper's planner stays in its way for good. With
    ``make_way`` the ego stands make_way_after (2 s), drives a short manoeuvre that ends clear of the car's path
    (shapely: the car's footprint swept 8 m north, grown by the vehicle margin) and keeps the margin to the car on the
    way, then stands aside, naming the car, until the car has moved 1 m. A car standing there facing away (it last
    drove south) is not waiting for the ego: the switch changes nothing."""
    from shapely.affinity import translate
    from shapely.geometry import Polygon
    from shapely.ops import unary_union

    from avp_world.geometry import rect_corners

    def scene(heading: float):
        back = -0.2 * math.sin(heading) * np.arange(6, -1, -1)[:, None] * np.array([[0.0, 1.0]])  # drove to y = 19
        hist = np.column_stack([np.full(7, 21.5), np.full(7, 19.0), np.full(7, heading)])
        hist[:, :2] += np.clip(back, -0.6, 0.6) * (np.arange(7) < 3)[:, None]
        car = ObservedVehicle(id=8, length=L, width=W, is_static=False, history=hist)
        standing = PredictedTrajectory(agent_id=8, poses=np.tile(hist[-1], (60, 1)), dt=0.1, length=L, width=W)
        return car, standing

    def run(planner, car, pred, steps):
        ego, out = np.array([21.5, 25.0, -math.pi / 2]), []
        for k in range(steps):
            d = planner.decide(replace(make_obs(paper_lot, ego, vacant=[], vehicles=[car]), step=k),
                               predictions=[pred])
            out.append((d, ego.copy()))
            if len(d.poses) > 1:
                ego = d.poses[1].copy()
        return out, ego

    car, pred = scene(math.pi / 2)
    fp = Polygon(rect_corners(car.pose, L, W))
    path = unary_union([fp, translate(fp, 0.0, 8.0)]).convex_hull.buffer(0.3, join_style=2)
    paper, _ = run(_planner(paper_lot), car, pred, 60)
    assert all(d.trace["mode"] != "make_way" for d, _ in paper) and paper[-1][0].command[0] == 0.0
    assert Polygon(rect_corners(paper[-1][1], L, W)).intersects(path)  # still in the car's way
    planner = _planner(paper_lot, make_way=True)
    steps, ego = run(planner, car, pred, 100)
    moving = [k for k, (d, _) in enumerate(steps) if d.trace["mode"] == "make_way"]
    assert moving and moving[0] == 20 and moving == list(range(20, moving[-1] + 1)), moving
    assert all(Polygon(rect_corners(e, L, W)).distance(fp) >= 0.3 - 1e-6 for _, e in steps)
    d, _ = steps[-1]
    assert d.command[0] == 0.0 and d.trace["cause"] == "making_way" and d.trace["agent_id"] == 8, d.trace
    assert not Polygon(rect_corners(ego, L, W)).intersects(path), ego
    gone = replace(car, history=np.vstack([car.history[1:], car.history[-1] + [0.0, 1.2, 0.0]]))
    nxt = planner.decide(replace(make_obs(paper_lot, ego, vacant=[], vehicles=[gone]), step=100),
                         predictions=[replace(pred, poses=np.tile(gone.history[-1], (60, 1)))])
    assert nxt.trace.get("cause") != "making_way", nxt.trace
    away, away_pred = scene(-math.pi / 2)
    steps, _ = run(_planner(paper_lot, make_way=True), away, away_pred, 40)
    assert all(d.trace["mode"] != "make_way" for d, _ in steps)
    assert all(d.trace["mode"] == "idle" for d, _ in steps[:30])  # stood past make_way_after all the same


def test_keep_plan_window_drives_on_past_a_late_meeting_and_stops_for_a_near_one(paper_lot):
    """``keep_plan_window`` (debouncing): a pedestrian appears standing in spot 14 after the ego has started its
    parking manoeuvre there. The paper's re-check drops the plan at once (the meeting is 5 s ahead); with a 2 s
    window the ego drives on, and drops the plan only as the meeting comes within 2 s — never nearer to the
    pedestrian than the pedestrian margin (shapely)."""
    from shapely.geometry import Point, Polygon

    from avp_world.geometry import rect_corners

    spot = paper_lot.spot_poses[paper_lot.spot_index(14)]
    walker = PredictedTrajectory(agent_id=5, poses=np.tile([spot[0], spot[1], 0.0], (60, 1)), dt=0.1,
                                 is_pedestrian=True, radius=0.3)

    def run(planner, steps=80):
        ego, out = np.array([21.5, 25.0, -math.pi / 2]), []
        for k in range(steps):
            d = planner.decide(replace(make_obs(paper_lot, ego, vacant=[14]), step=k),
                               predictions=[] if k == 0 else [walker])
            out.append((d, ego.copy()))
            if len(d.poses) > 1:
                ego = d.poses[1].copy()
        return out

    paper = run(_planner(paper_lot), 3)
    assert paper[0][0].mode == "park" and paper[1][0].mode != "park"
    kept = run(_planner(paper_lot, keep_plan_window=2.0))
    dropped = next(k for k, (d, _) in enumerate(kept) if d.mode != "park")
    assert dropped > 20, dropped  # driven on for more than 2 s after the walker appeared
    assert all(d.reason == "executing" for d, _ in kept[1:dropped])
    disc = Point(spot[0], spot[1]).buffer(0.3, 64)
    assert min(Polygon(rect_corners(e, L, W)).distance(disc) for _, e in kept) >= 0.4 - 1e-6


def test_most_likely_hypothesis_checks_only_each_agents_most_probable_trajectory(paper_lot):
    """``collision.hypotheses: most_likely``: the car south of the ego is predicted to stand (probability 0.6) or to
    drive north through the ego's manoeuvre into spot 14 (0.4). Every hypothesis blocks the paper's plan; with only
    the most probable one checked the ego parks. Made the more probable, the moving one blocks again."""
    car, moving = _standing_car_and_its_moving_hypothesis(probability=0.4)
    standing = replace(moving, poses=np.tile(car.pose, (60, 1)), probability=0.6)
    obs = make_obs(paper_lot, (21.5, 25.0, -math.pi / 2), vacant=[14], vehicles=[car])
    paper = _planner(paper_lot).decide(obs, predictions=[moving, standing])
    assert paper.command[0] == 0.0 and paper.trace.get("agent_id") == 8, paper.trace
    d = _planner(paper_lot, hypotheses="most_likely").decide(obs, predictions=[moving, standing])
    assert d.mode == "park" and d.spot_id == 14 and d.command[0] != 0.0, d.trace
    d = _planner(paper_lot, hypotheses="most_likely").decide(
        obs, predictions=[replace(moving, probability=0.6), replace(standing, probability=0.4)])
    assert d.command[0] == 0.0 and d.trace.get("agent_id") == 8, d.trace


def test_receding_straight_replaces_the_curves_of_a_car_driving_away(paper_lot):
    """``collision.receding: straight``: a car 10 m south of the ego drives south, away from it, at 2 m/s; one of its
    hypotheses (0.5) turns back north through the ego's manoeuvre into spot 14. It blocks the paper's plan; predicted
    straight on instead, the car is gone south and the ego parks. The same car and hypothesis with the car driving
    north, towards the ego, still block."""
    def car_and_curve(heading: float):
        y = 13.0 + 0.2 * math.sin(heading) * np.arange(-6, 1)  # 2 m/s along its heading, at y = 13 now
        hist = np.column_stack([np.full(7, 21.5), y, np.full(7, heading)])
        car = ObservedVehicle(id=8, length=L, width=W, is_static=False, history=hist)
        n = 60
        back = np.column_stack([np.full(n, 21.5), 13.0 + 0.2 * np.arange(1, n + 1), np.full(n, math.pi / 2)])
        return car, PredictedTrajectory(agent_id=8, poses=back, dt=0.1, length=L, width=W, probability=0.5)

    away, curve = car_and_curve(-math.pi / 2)
    obs = make_obs(paper_lot, (21.5, 25.0, -math.pi / 2), vacant=[14], vehicles=[away])
    paper = _planner(paper_lot).decide(obs, predictions=[curve])
    assert paper.command[0] == 0.0 and paper.trace.get("agent_id") == 8, paper.trace
    assert paper.trace["motion"] == "away"
    d = _planner(paper_lot, receding="straight").decide(obs, predictions=[curve])
    assert d.mode == "park" and d.spot_id == 14 and d.command[0] != 0.0, d.trace
    towards, curve = car_and_curve(math.pi / 2)
    obs = make_obs(paper_lot, (21.5, 25.0, -math.pi / 2), vacant=[14], vehicles=[towards])
    d = _planner(paper_lot, receding="straight").decide(obs, predictions=[curve])
    assert d.command[0] == 0.0 and d.trace.get("agent_id") == 8, d.trace


def test_reactive_model_hold_predicts_a_reacting_car_where_it_is(paper_lot):
    """``collision.reactive_model: hold``: a car 12 m south of the ego drives north at 2 m/s, predicted through the
    ego's manoeuvre into spot 14. Rolled out with the braking rule (every agent assumed to react) it still meets the
    plan; held where it is, as blind holds every agent, it does not, and the ego parks. With the reaction learnt from
    evidence (`lot`) and none seen yet, the car is not held and blocks as in the paper."""
    y = 13.0 + 0.2 * np.arange(-6, 1)
    car = ObservedVehicle(id=8, length=L, width=W, is_static=False,
                          history=np.column_stack([np.full(7, 21.5), y, np.full(7, math.pi / 2)]))
    pred = PredictedTrajectory(agent_id=8, poses=np.column_stack([np.full(60, 21.5), 13.0 + 0.2 * np.arange(1, 61),
                                                                  np.full(60, math.pi / 2)]), dt=0.1, length=L, width=W)
    obs = make_obs(paper_lot, (21.5, 25.0, -math.pi / 2), vacant=[14], vehicles=[car])
    rollout = _planner(paper_lot, reactive_steps=2, reactive_evidence="assumed").decide(obs, predictions=[pred])
    assert rollout.command[0] == 0.0 and rollout.trace.get("agent_id") == 8, rollout.trace
    hold = _planner(paper_lot, reactive_steps=2, reactive_evidence="assumed", reactive_model="hold")
    d = hold.decide(obs, predictions=[pred])
    assert d.mode == "park" and d.spot_id == 14 and d.command[0] != 0.0, d.trace
    unseen = _planner(paper_lot, reactive_steps=2, reactive_evidence="lot", reactive_model="hold")
    d = unseen.decide(obs, predictions=[pred])
    assert d.command[0] == 0.0 and d.trace.get("agent_id") == 8, d.trace

"""Several automated cars in one lot (avp_sim.core.egos, avp_episode.fleet): hand-built scenes on the paper lot,
shapely as the judge of where the egos end up."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from shapely.geometry import Polygon

from avp_episode.fleet import parse_fleet, run_fleet_inproc, waits_for
from avp_episode.gridlock import GridlockMeter, find_cycle
from avp_episode.run_config import RunConfig, run_profile, sim_values
from avp_sim.core.egos import EGO_ID_BASE
from avp_sim.core.scenario_file import scenario_from_dict
from avp_sim.core.world import SUCCESS, World, WorldConfig
from avp_world.geometry import rect_corners

DOWN, UP = -math.pi / 2, math.pi / 2
GATE = [21.5, 38.0, DOWN]  # the paper's start: top of the middle road


def _scene(paper_lot, vacant, egos, seed=3):
    return scenario_from_dict(paper_lot, {"seed": seed, "reactive": True, "ego_start": GATE, "vacant_spot_ids": vacant,
                                          "egos": egos}, "test scene", seed, True)


def _fleet(paper_lot, vacant, egos, methods=("bezier", "bezier"), t_final=60.0, gate=GATE):
    cfg = RunConfig(t_final=t_final)
    sim = sim_values(cfg)
    data = {"seed": 3, "reactive": True, "ego_start": gate, "vacant_spot_ids": vacant, "egos": egos}
    return run_fleet_inproc(paper_lot, sim, [run_profile(m, cfg) for m in methods], 3, True, cfg,
                            scenario=("test scene", data))


def _inside(paper_lot, pose, spot_id) -> bool:
    spot = Polygon(paper_lot.spot_corners[paper_lot.spot_index(spot_id)])
    return spot.buffer(1e-6).contains(Polygon(rect_corners(np.asarray(pose), 4.6, 1.85)))


def test_one_ego_is_the_world_as_before(paper_lot):
    """K = 1: World.step drives the one ego; step_all with one command is the same step; observations name no ego."""
    sc = _scene(paper_lot, [17, 26], [])
    a, b = World(paper_lot, sc), World(paper_lot, sc)
    for _ in range(30):
        a.step(1.0, 0.1)
        b.step_all([(1.0, 0.1)])
    assert np.array_equal(a.ego, b.ego) and a.metrics == b.metrics
    assert all(v.id < EGO_ID_BASE for v in a.observe().vehicles)
    with pytest.raises(ValueError, match="use step_all"):
        World(paper_lot, sc, WorldConfig(n_egos=2)).step(1.0, 0.0)


def test_egos_enter_one_after_another_and_see_each_other(paper_lot):
    """egos.entry_interval: ego 1 enters at the gate 5 s after ego 0, once the gate is clear; to ego 1, ego 0 is an
    observed vehicle (its pose history, nothing else), and a parked ego is a parked car."""
    w = World(paper_lot, _scene(paper_lot, [17, 26], []), WorldConfig(n_egos=2, entry_interval=5.0))
    assert list(w.egos.present) == [True, False]
    with pytest.raises(ValueError, match="not entered"):
        w.observe(1)
    for _ in range(50):  # ego 0 drives 10 m down the middle road: the gate is clear at 5 s
        w.step_all([(2.0, 0.0), (5.0, 0.0)])
    assert list(w.egos.present) == [True, True] and w.egos.entered_step[1] == 50
    assert np.allclose(w.egos.poses[1], GATE)  # its command before it entered was ignored
    seen = {v.id: v for v in w.observe(1).vehicles}
    assert EGO_ID_BASE + 0 in seen and np.allclose(seen[EGO_ID_BASE].history[-1], w.egos.poses[0])
    assert EGO_ID_BASE + 1 in {v.id for v in w.observe(0).vehicles}


def test_two_egos_two_spots_both_park_and_nobody_loses_a_spot(paper_lot):
    recs = _fleet(paper_lot, [17, 26], [])
    assert [r["status"] for r in recs] == [SUCCESS, SUCCESS], recs
    assert {r["parked_spot_id"] for r in recs} == {17, 26}
    assert all(r["spots_lost_to_ego"] == 0 and r["spots_lost_to_agent"] == 0 for r in recs)
    assert not any(r["collision"] for r in recs) and recs[1]["entered_s"] == 5.0
    assert recs[0]["fleet"] == "bezier,bezier" and [r["ego"] for r in recs] == [0, 1]


@pytest.mark.slow
def test_two_egos_one_spot_one_parks_the_other_lost_it_to_that_ego(paper_lot):
    """Both start at t = 0 equally far from the one free spot, at the two ends of the middle road."""
    recs = _fleet(paper_lot, [14], [{"start": [21.5, 3.5, UP], "enter_at": 0.0}], t_final=40.0)
    parked = [r for r in recs if r["status"] == SUCCESS]
    assert len(parked) == 1 and parked[0]["parked_spot_id"] == 14, recs
    assert _inside(paper_lot, parked[0]["final_pose"], 14)
    other = next(r for r in recs if r is not parked[0])
    assert other["spots_lost_to_ego"] == 1 and other["spots_lost_to_agent"] == 0
    assert not any(r["collision"] for r in recs)
    assert recs[0]["gridlock"] == (_mutual_wait_s(recs) >= 5.0)


def test_find_cycle_and_gridlock_meter():
    ego0, ego1, car = ("ego", 0), ("ego", 1), ("agent", 7)
    assert find_cycle({ego0: {ego1}, ego1: {ego0}}) == frozenset({ego0, ego1})
    assert find_cycle({ego0: {car}, car: {ego0}}) == frozenset({ego0, car})
    assert find_cycle({ego0: {ego1}, ego1: {car}}) is None
    m = GridlockMeter(dt=0.1, min_s=5.0)
    for k in range(49):  # 4.9 s: not yet
        m.add(k, {ego0: {ego1}, ego1: {ego0}})
    m.add(49, {ego0: {ego1}})
    assert not m.summary(49)["gridlock"]
    m = GridlockMeter(dt=0.1, min_s=5.0)
    for k in range(60):
        m.add(k, {ego0: {ego1}, ego1: {ego0}})
    s = m.summary(59)
    assert s["gridlock"] and s["gridlock_s"] == 6.0 and s["gridlock_spells"][0]["members"] == ["ego:0", "ego:1"]


def test_waits_for_reads_the_traces_and_the_agents_brakes(paper_lot):
    from types import SimpleNamespace

    w = World(paper_lot, _scene(paper_lot, [17], [{"start": [21.5, 20.0, UP], "enter_at": 0.0}]))
    stand = SimpleNamespace(mode="idle", command=(0.0, 0.0),
                            trace={"mode": "idle", "cause": "agent", "agent_id": EGO_ID_BASE + 1, "pedestrian": False})
    drive = SimpleNamespace(mode="park", command=(1.0, 0.0), trace={"mode": "park"})
    assert waits_for(w, {0: stand, 1: drive}) == {("ego", 0): {("ego", 1)}}


def test_parse_fleet_errors():
    assert parse_fleet("bezier", 3) == ["bezier"] * 3
    assert parse_fleet("bezier,blind") == ["bezier", "blind"]
    for spec, k, msg in (("", None, "comma-separated"), ("bezier,,blind", None, "comma-separated"),
                         ("bezier", 9, "1..8"), ("bezier,blind", 3, "names 2 methods")):
        with pytest.raises(ValueError, match=msg):
            parse_fleet(spec, k)


def _mutual_wait_s(recs, dt=0.1) -> float:
    """Seconds in which both egos' idle spells name each other as the blocker (from their decision traces)."""
    steps = []
    for i, r in enumerate(recs):
        other = EGO_ID_BASE + (1 - i)
        s = set()
        for spell in r["decision_trace"]["idle_spells"]:
            if other in spell.get("blocking_agents", []):
                k0 = round(spell["start_s"] / dt)
                s.update(range(k0, k0 + round(spell["seconds"] / dt)))
        steps.append(s)
    return len(steps[0] & steps[1]) * dt


def test_two_egos_face_to_face_in_one_aisle(paper_lot):
    """Face to face 10 m apart in the middle road, a free spot ahead of each beyond the other and one behind each.
    No collision; the gridlock metric fires exactly when both stood waiting on each other for 5 s (here neither
    waits: each reverses into the spot behind it)."""
    data = [{"start": [21.5, 16.0, UP], "enter_at": 0.0}]
    recs = _fleet(paper_lot, [20, 19], data, t_final=40.0, gate=[21.5, 26.0, DOWN])
    assert not any(r["collision"] for r in recs), [r["collision_with"] for r in recs]
    assert recs[0]["gridlock"] == recs[1]["gridlock"]
    assert recs[0]["gridlock"] == (_mutual_wait_s(recs) >= 5.0), (recs[0]["gridlock_spells"], _mutual_wait_s(recs))
    assert [r["status"] for r in recs] == [SUCCESS, SUCCESS]
    assert all(_inside(paper_lot, r["final_pose"], r["parked_spot_id"]) for r in recs)  # shapely: in its spot


@pytest.mark.parametrize("egos, needle", [
    ({"start": GATE}, "egos: expected a list"),
    ([{"start": GATE}] * 8, "at most 7"),
    ([{"start": GATE, "speed": 1}], "egos[0].speed: unknown key"),
    ([{"start": [21.5, 38.0]}], "egos[0].start: expected [x, y, theta]"),
    ([{"start": [500.0, 38.0, 0.0]}], "egos[0].start: the ego's footprint is outside the lot"),
    ([{"start": GATE, "enter_at": -1.0}], "egos[0].enter_at: -1.0 is outside"),
])
def test_bad_egos_in_a_scenario_file_get_one_error_naming_the_field(paper_lot, egos, needle):
    from avp_scenario.scenario import ScenarioError

    with pytest.raises(ScenarioError) as e:
        _scene(paper_lot, [17], egos)
    assert "test scene: " in str(e.value) and needle in str(e.value)


@pytest.mark.slow
def test_avp_experiment_runs_fleets_with_a_record_per_ego_and_resumes(tmp_path, capsys):
    """``avp experiment --egos 2`` (a fleet of each method) and ``--fleet`` (one mixed fleet): a record per ego,
    the fleet table, and the same command again runs nothing."""
    from avp_experiment.results import RESULTS_FILE, read_results
    from avp_experiment.runner import main

    common = ["--scenarios", "1", "--seed-base", "4", "--mode", "reactive", "--workers", "0", "--t-final", "30",
              "--no-progress"]
    out = tmp_path / "k2"
    assert main([*common, "--egos", "2", "--methods", "blind", "--out", str(out)]) == 0
    recs = read_results(out / RESULTS_FILE)
    assert [(r["method"], r["ego"], r["ego_method"], r["seed"]) for r in recs] == [
        ("fleet:blind,blind", 0, "blind", 4), ("fleet:blind,blind", 1, "blind", 4)]
    assert "| blind,blind | reactive | 2 |" in (out / "fleet.md").read_text()
    capsys.readouterr()
    assert main([*common, "--egos", "2", "--methods", "blind", "--out", str(out)]) == 0
    assert "0 to run" in capsys.readouterr().out and len(read_results(out / RESULTS_FILE)) == 2
    mixed = tmp_path / "mixed"
    assert main([*common, "--fleet", "blind,bezier", "--out", str(mixed)]) == 0
    assert [r["ego_method"] for r in read_results(mixed / RESULTS_FILE)] == ["blind", "bezier"]


@pytest.mark.parametrize("args, needle", [
    (["--egos", "9", "--methods", "blind"], "--egos: expected 1..8"),
    (["--fleet", "blind,,bezier"], "--fleet: expected comma-separated"),
    (["--fleet", "blind,bezier", "--egos", "3"], "--fleet names 2 methods but --egos is 3"),
])
def test_bad_fleet_arguments_get_one_line(tmp_path, capsys, args, needle):
    from avp_experiment.runner import main

    assert main([*args, "--scenarios", "1", "--no-progress", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err


def test_the_reservation_book_refuses_a_second_claim_and_frees_a_dead_egos_spot():
    from types import SimpleNamespace

    from avp_planner.core.reservation import SpotReservations

    book = SpotReservations(timeout=2.0)
    assert book.claim(0, 14, now=0.0) and book.holder(14) == 0
    assert not book.claim(1, 14, now=0.5) and book.refused == 1  # first come, first served
    assert book.claim(0, 14, now=1.0)  # the holder may claim again (a heartbeat)
    assert book.claim(1, 17, now=1.0) and book.held_by_others(0) == {17}
    assert book.claim(1, 18, now=1.5) and book.holder(17) is None  # one hold per ego: the new one frees the old
    book.update(0, SimpleNamespace(mode="idle", spot_id=-1), now=2.5)  # waiting keeps the hold
    assert book.holder(14) == 0
    book.heartbeat(1, 4.0)
    assert book.expire(4.6) == [0] and book.holder(14) is None  # ego 0 silent for more than 2 s: its spot is free
    assert book.claim(1, 14, now=4.7) and book.holder(18) is None
    book.update(1, SimpleNamespace(mode="explore", spot_id=-1), now=5.0)  # gave the spot up
    assert book.by_ego == {}
    with pytest.raises(ValueError, match="timeout"):
        SpotReservations(timeout=0.0)


def test_reserve_hides_the_spots_other_egos_hold_and_one_ego_parks_without_a_fight(paper_lot):
    from avp_planner.core.reservation import SpotReservations

    book = SpotReservations()
    world = World(paper_lot, _scene(paper_lot, [14, 17], [{"start": [21.5, 3.5, UP], "enter_at": 0.0}]),
                  WorldConfig(n_egos=2))
    world.step_all([(0.0, 0.0), (0.0, 0.0)])  # ego 1 enters after the first step
    obs = world.observe(0)
    assert obs.vacant_spot_ids.tolist() == [17]  # ego 0 sees spot 17 vacant
    assert book.apply(obs, 0) is obs  # nothing hidden while nobody holds a spot
    book.claim(1, 17, now=0.0)
    seen = book.apply(obs, 0)
    assert seen.vacant_spot_ids.tolist() == [] and set(seen.occupied_spot_ids) == {*obs.occupied_spot_ids, 17}
    assert book.apply(obs, 1) is obs  # its own hold is not hidden from ego 1
    recs = _fleet(paper_lot, [14], [{"start": [21.5, 3.5, UP], "enter_at": 0.0}], methods=("reserve", "reserve"),
                  t_final=40.0)
    parked = [r for r in recs if r["status"] == SUCCESS]
    assert len(parked) == 1 and _inside(paper_lot, parked[0]["final_pose"], 14), recs
    assert not any(r["collision"] for r in recs)
    assert recs[0]["fleet"] == "reserve,reserve"


def test_reserve_needs_several_egos_and_the_fleet_graph_gives_it_the_reservation_node():
    from avp_episode.profiles import ProfileError, load_profile, method_node_params
    from avp_experiment.runner import resolve_methods

    run, skipped = resolve_methods("bezier,reserve")
    assert [p.name for p in run] == ["bezier"] and "--egos" in skipped["reserve"]
    run, skipped = resolve_methods("bezier,reserve", egos=2)
    assert [p.name for p in run] == ["bezier", "reserve"] and not skipped
    with pytest.raises(ProfileError, match="among several egos"):
        method_node_params(load_profile("reserve"))  # one ego alone: nobody to reserve against
    run, skipped = resolve_methods("bezier,reserve", transport="ros", egos=2)
    assert [p.name for p in run] == ["bezier", "reserve"] and not skipped
    from avp_bringup.graph import fleet_graph

    nodes = {n.key: n for n in fleet_graph(["bezier", "reserve", "reserve"], processes="node")}
    book, radio = nodes["avp_reservation"], nodes["avp_v2v"]
    assert book.extra_params["egos"] == "1,2" and book.extra_params["lockstep"] is True
    assert radio.extra_params["egos"] == "0,1,2" and radio.extra_params["lockstep"] is True
    # the book (and the V2V node) wait for the reserve pipelines themselves
    assert nodes["avp_sim"].extra_params["min_subscribers"] == 2
    for key in ("avp_belief", "avp_prediction", "avp_planner"):  # ego 0 reads the simulator; 1 and 2 the book
        assert ("observation", "reserved/observation") not in nodes[f"ego0.{key}"].remaps
        assert ("observation", "reserved/observation") in nodes[f"ego1.{key}"].remaps
        assert ("observation", "reserved/observation") in nodes[f"ego2.{key}"].remaps
    assert all(nodes[f"ego{i}.avp_planner"].extra_params["use_beacons"] is True for i in range(3))  # V2V heard


def test_the_simulator_names_which_ego_each_braking_agent_brakes_for(paper_lot):
    """debug/braking_for (several egos) carries World.braking_for as (agent id, ego) pairs in its row-major order,
    which the DDS transport's collector feeds to the gridlock metric as the in-process fleet does."""
    pytest.importorskip("rclpy")
    from builtin_interfaces.msg import Time

    from avp_episode.fleet_metrics import wait_edges
    from avp_sim.sim_node import braking_for_msg

    w = World(paper_lot, _scene(paper_lot, [17], [{"start": [21.5, 20.0, UP], "enter_at": 0.0}]),
              WorldConfig(n_egos=2))
    assert braking_for_msg(w, Time()).agent_ids.tolist() == []
    rows = np.array([0, len(w.states) - 1])  # any two of its cars (the message does not ask why they brake)
    w.braking_for[rows[0], 1] = w.braking_for[rows[1], 0] = w.braking_for[rows[1], 1] = True
    msg = braking_for_msg(w, Time())
    ids = [int(w.vehicle_ids[r]) for r in rows]
    assert list(zip(msg.agent_ids, msg.ego_indices, strict=True)) == [(ids[0], 1), (ids[1], 0), (ids[1], 1)]
    assert msg.step == w.step_index
    assert waits_for(w, {}) == wait_edges([], zip(msg.agent_ids, msg.ego_indices, strict=True), EGO_ID_BASE) == {
        ("agent", ids[0]): {("ego", 1)}, ("agent", ids[1]): {("ego", 0), ("ego", 1)}}


def test_the_live_graph_of_k_egos_its_topics_and_its_frames():
    from avp_bag.recorder import GRAPH_TOPICS, fleet_topics
    from avp_bringup.cli import _fleet_methods, build_parser
    from avp_bringup.graph import Graph, fleet_graph
    from avp_viz import scene

    nodes = fleet_graph(["bezier", "blind", "bezier"], scene=True, processes="node")  # one process each
    assert nodes[0].extra_params["egos.count"] == 3 and nodes[0].extra_params["min_subscribers"] == 5
    assert nodes[-1].key == "avp_v2v"  # 3 nodes, the scene and the V2V node read each ego's observation
    assert [n.key for n in nodes[1:5]] == ["ego0.avp_belief", "ego0.avp_prediction", "ego0.avp_planner",
                                           "ego0.avp_scene"]
    assert {n.namespace for n in nodes[1:-1]} == {"/avp/ego0", "/avp/ego1", "/avp/ego2"}
    cmd = Graph(nodes, Path("/tmp")).command(nodes[6])  # ego 1's prediction node: blind's predictor
    assert "__ns:=/avp/ego1" in cmd and "lot_map:=/avp/lot_map" in cmd
    assert fleet_graph(["bezier"])[0].extra_params.get("egos.count", 1) == 1  # one method: the one-ego graph
    p = build_parser()
    assert _fleet_methods(p.parse_args(["launch", "--egos", "2"])) == ["bezier", "bezier"]
    assert _fleet_methods(p.parse_args(["launch"])) == []
    for bad, needle in ((["--egos", "9"], "--egos: expected 1..8"), (["--methods", "a,,b"], "--methods: expected"),
                        (["--methods", "bezier", "--method", "blind"], "exclude each other")):
        with pytest.raises(ValueError, match=needle):
            _fleet_methods(p.parse_args(["launch", *bad]))
    topics = fleet_topics(2)
    assert "/avp/observation" not in topics and "/avp/ego1/observation" in topics and "/avp/episode_status" in topics
    assert "/avp/ego0/viz/scene" in topics and "/avp/debug/ground_truth" in topics and fleet_topics(1) == GRAPH_TOPICS
    from types import SimpleNamespace

    obs = SimpleNamespace(ego_pose=(1.0, 2.0, 0.0), vehicles=[SimpleNamespace(id=5, pose=(3.0, 4.0, 0.0))])
    from builtin_interfaces.msg import Time

    tf = scene.transforms(obs, Time(), "ego1/")
    assert [(t.header.frame_id, t.child_frame_id) for t in tf.transforms] == [("ego1/odom", "ego1/base_link"),
                                                                             ("map", "ego1/agent_5")]


def _spot_pose(lot, spot_id: int, shift: float = 0.0) -> np.ndarray:
    """A pose at the centre of a spot, heading along its long side, moved ``shift`` m along it."""
    c = np.asarray(lot.spot_corners[lot.spot_index(spot_id)], dtype=float)
    sides = [c[1] - c[0], c[2] - c[1]]
    long = max(sides, key=np.linalg.norm)
    u = long / np.linalg.norm(long)
    x, y = c.mean(axis=0) + shift * u
    return np.array([x, y, math.atan2(u[1], u[0])])


def test_the_occupancy_with_egos_is_the_stacked_classification(paper_lot):
    """World.occupancy_with (the agents' per-step classification, then the egos alone) gives what classifying
    every agent and ego together gives, and a parked ego holds its spot (shapely judges which ego lies inside)."""
    from avp_episode.fleet import _holders
    from avp_episode.fleet_metrics import spot_holders
    from avp_sensing.observation import classify_world

    w = World(paper_lot, _scene(paper_lot, [17, 26], []), WorldConfig(n_egos=3))
    w.egos.present[:] = True
    w.egos.poses[1] = _spot_pose(paper_lot, 17)  # inside spot 17
    w.egos.poses[2] = _spot_pose(paper_lot, 26, shift=3.0)  # half out of spot 26
    assert _inside(paper_lot, w.egos.poses[1], 17) and not _inside(paper_lot, w.egos.poses[2], 26)
    for rows in ([], [1], [0, 2], [0, 1, 2]):
        rows = np.array(rows, dtype=np.int64)
        corners = np.concatenate([w.vehicle_corners(), w.egos.corners(rows)]) if len(rows) else w.vehicle_corners()
        want = classify_world(paper_lot, corners)
        got = w.occupancy_with(rows)
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
    holders = _holders(w)
    assert holders == spot_holders(paper_lot, w.vehicle_corners(), w.egos.corners(np.arange(3)), range(3))
    assert holders[17] == "ego:1" and 26 not in holders
    seen = {v.id: v.is_static for i in range(3) for v in w.observe(i).vehicles if v.id >= EGO_ID_BASE}
    assert seen == {EGO_ID_BASE: False, EGO_ID_BASE + 1: True, EGO_ID_BASE + 2: False}

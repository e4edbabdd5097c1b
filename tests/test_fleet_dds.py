"""Several egos over DDS (docs/world.md, "Several egos"): the simulator with ``egos.count`` K and K pipelines in
/avp/ego<i>, as real processes on a ROS domain of the test's own.

* two egos of the shipped default through the live graph in lock-step equal the in-process fleet
  (:func:`avp_episode.fleet.run_fleet_inproc`) bit for bit, ego by ego;
* lock-step waits for every driving ego's command, and after ``lockstep_timeout`` names the egos that did not
  answer; a command for ego 0 tagged with ego 1's key (ego 1's planner, or a copy of its command) is dropped;
* keys: a node in /avp/ego<i> tags with ego i's key, which verifies on ego i's topics only;
* ``avp experiment --transport ros --egos 2`` gives the in-process fleet's records, spots lost and gridlock included;
* with four egos on seed 29, where ego 3 gives way to ego 0 (``decision.ego_yield``), the beacons relayed by the V2V
  node give the in-process records too.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

SEED = 6  # both egos park (ego 0 at 12.9 s, ego 1 at 32.3 s, in process)
T_FINAL = 40.0


def test_a_node_in_an_egos_namespace_tags_with_that_egos_key(ros_env, monkeypatch):
    from avp_common.msg_auth import Authenticator, ego_scope, load_key, scoped_key, sign, verify
    from avp_msgs.msg import Observation

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    assert ego_scope("/avp/ego1/cmd") == "ego1" and ego_scope("/avp/ego12") == "ego12"
    assert ego_scope("/avp/cmd") is None and ego_scope("/avp/lot_map") is None and ego_scope("/avp/egos/x") is None
    rclpy.init()
    try:
        n1 = rclpy.create_node("planner_1", namespace="/avp/ego1")
        n0 = rclpy.create_node("sim", namespace="/avp")
        a1, a0 = Authenticator(n1), Authenticator(n0)
        master = load_key()
        assert a0.key == master and a1.key == scoped_key(master, "ego1") != master
        assert a1.publisher(Observation, "cmd_probe", 10)._key == a1.key  # what its publishers tag with
        assert a0.publisher(Observation, "ego1/observation", 10, ego=1)._key == a1.key  # the simulator's per ego
        msg = Observation()
        raw = sign(a1.key, msg)
        assert verify(a0.key_for("/avp/ego1/cmd"), raw)  # on ego 1's topics
        assert not verify(a0.key_for("/avp/ego0/cmd"), raw)  # not on ego 0's
        assert not verify(a0.key_for("/avp/cmd"), raw)  # nor on the one-ego graph's
        raw0 = sign(master, msg)
        assert verify(a0.key_for("/avp/lot_map"), raw0) and not verify(a0.key_for("/avp/ego1/cmd"), raw0)
        n1.destroy_node()
        n0.destroy_node()
    finally:
        rclpy.try_shutdown()


def _inprocess_fleet(lot, cfg, methods):
    from avp_episode.fleet import run_fleet_inproc
    from avp_episode.run_config import run_profile, sim_values

    keep: dict = {}
    records = run_fleet_inproc(lot, sim_values(cfg), [run_profile(m, cfg) for m in methods], SEED, True, cfg,
                               keep=keep)
    return records, keep["world"]


def test_two_egos_over_dds_match_inprocess(paper_lot, ros_env, tmp_path, monkeypatch):
    """K = 2 over DDS, each ego's pipeline in one process (the default layout): every ego's trajectory bit for bit
    the in-process fleet's."""
    from avp_bringup.graph import Graph, fleet_graph
    from avp_episode.run_config import RunConfig, run_profile, sim_values
    from avp_monitor.monitor import EpisodeMonitor

    cfg = RunConfig(t_final=T_FINAL)
    records, world = _inprocess_fleet(paper_lot, cfg, ["bezier", "bezier"])
    assert [r["success"] for r in records] == [True, True]  # the reference exercises both pipelines
    log_egos = np.asarray(world.log_egos)
    expected = [log_egos[int(world.egos.entered_step[i]):, i] for i in range(2)]

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    sim_p = sim_values(cfg)
    nodes = fleet_graph([run_profile("bezier", cfg)] * 2, deterministic=True, sim_extra={
        "t_final": T_FINAL, "seed": SEED, "reactive": True, "publish_markers": False, "min_debug_subscribers": 1,
        "egos.entry_interval": sim_p["egos.entry_interval"]})
    # each ego's belief, prediction and planner nodes in one component container (avp_bringup.compose)
    assert [n.key for n in nodes] == ["avp_sim", "ego0.pipeline", "ego1.pipeline", "avp_v2v"]
    assert nodes[2].member_keys == ["ego1.avp_belief", "ego1.avp_prediction", "ego1.avp_planner"]
    rclpy.init()
    monitor = EpisodeMonitor()
    graph = Graph(nodes, tmp_path / "logs", env=ros_env)
    graph.start()
    try:
        t0 = time.monotonic()
        while not monitor.finished and time.monotonic() - t0 < 600:
            rclpy.spin_once(monitor, timeout_sec=0.1)
            assert all(rc is None for rc in graph.poll().values()), graph.poll()
        assert monitor.finished, "episode did not finish over DDS"
        t1 = time.monotonic()
        while len(monitor.gt) < monitor.status.step + 1 and time.monotonic() - t1 < 30:
            rclpy.spin_once(monitor, timeout_sec=0.05)
        got = [monitor.ego_trajectory(i) for i in range(2)]
    finally:
        graph.stop()
        monitor.destroy_node()
        rclpy.try_shutdown()
    for i in range(2):
        assert got[i].shape == expected[i].shape, (i, got[i].shape, expected[i].shape)
        assert np.array_equal(got[i], expected[i]), i  # bit-identical, ego by ego
    assert monitor.status.step == world.step_index


def test_fleet_experiment_over_dds_gives_the_inprocess_records(paper_lot, ros_env, tmp_path, monkeypatch):
    """The experiment's DDS transport with two egos (the fleet graph, its reset, the fleet collector) writes the
    records of the in-process fleet, field by field apart from the timings: the spot-reservation reference on seed
    85, through the reservation node (avp_planner.reservation_node), where ego 0 loses a spot to ego 1 and one to an
    agent and times out at t_f = 40 s, and ego 1 parks. (A fleet of the shipped default over DDS is compared pose by
    pose in test_two_egos_over_dds_match_inprocess and parks in test_demo_of_two_egos_parks_both_and_records_both.)"""
    from avp_episode.fleet import fleet_label, run_fleet_inproc
    from avp_episode.run_config import RunConfig, run_profile, sim_values
    from avp_experiment_ros.transport import run_ros

    cfg = RunConfig(t_final=40.0)
    keys = [(fleet_label(["reserve", "reserve"]), 85, "reactive")]
    expected = run_fleet_inproc(paper_lot, sim_values(cfg), [run_profile("reserve", cfg)] * 2, 85, True, cfg)
    assert [(r["ego_method"], r["spots_lost_to_ego"], r["spots_lost_to_agent"], r["status"]) for r in expected] == [
        ("reserve", 1, 1, "timeout"), ("reserve", 0, 0, "success")]  # what the seed exercises
    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    got: list[dict] = []
    run_ros(keys, cfg, lambda recs: got.extend(recs), tmp_path / "logs", timeout=900.0, env=ros_env)
    assert len(got) == 2
    for g, e in zip(got, expected, strict=True):
        assert g["transport"] == "ros" and g["timings"]["decisions"] == e["timings"]["decisions"] > 0
        same = {k: v for k, v in g.items() if k not in ("timings", "transport")}
        assert same == {k: v for k, v in e.items() if k not in ("timings", "transport")}, (g["seed"], g["ego"])


def test_an_ego_gives_way_over_dds_as_in_process(paper_lot, ros_env, tmp_path, monkeypatch):
    """Four egos on seed 29 (the paper lot's one ego-ego gridlock without ego_yield, tests/test_ego_yield.py): in
    process, ego 3 (the later) gives way to ego 0's announced path, no gridlock forms and nobody collides; over DDS,
    where ego 3 reads that path from the beacons the V2V node (avp_planner.v2v_node) relays, every ego's record is
    the in-process one."""
    from avp_episode.fleet import fleet_label, run_fleet_inproc
    from avp_episode.run_config import RunConfig, run_profile, sim_values
    from avp_experiment_ros.transport import run_ros

    cfg = RunConfig(t_final=46.0)  # ego 3 stands from 39.0 s and makes way for 2 s from 42.9 s
    expected = run_fleet_inproc(paper_lot, sim_values(cfg), [run_profile("bezier", cfg)] * 4, 29, True, cfg)
    # the later ego gives way; ego 0 has the right of way
    assert [r["decision_trace"]["steps_by_mode"].get("make_way", 0) > 0 for r in expected] == [False] * 3 + [True]
    assert not any(r["gridlock"] or r["collision"] for r in expected)
    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    got: list[dict] = []
    run_ros([(fleet_label(["bezier"] * 4), 29, "reactive")], cfg, lambda recs: got.extend(recs), tmp_path / "logs",
            timeout=900.0, env=ros_env)
    assert len(got) == 4
    for g, e in zip(got, expected, strict=True):
        same = {k: v for k, v in g.items() if k not in ("timings", "transport")}
        assert same == {k: v for k, v in e.items() if k not in ("timings", "transport")}, g["ego"]


def test_lockstep_waits_for_every_ego_and_names_the_late_one(ros_env, tmp_path, monkeypatch):
    from geometry_msgs.msg import TwistStamped

    from avp_bringup.graph import Graph, NodeSpec
    from avp_common.conversions import time_to_ns
    from avp_common.msg_auth import episode_of, load_key, scoped_key, sign, with_episode
    from avp_common.qos import STEP
    from avp_msgs.msg import EpisodeStatus, Observation

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    sim = NodeSpec("avp_sim", "avp_sim", "sim_node", "config/sim.param.yaml", {
        "egos.count": 2, "egos.entry_interval": 0.5, "min_subscribers": 1, "lockstep_timeout": 1.0,
        "publish_markers": False, "seed": 1, "t_final": 30.0})
    rclpy.init()
    node = rclpy.create_node("probe", namespace="/avp")
    master = load_key()
    keys = [scoped_key(master, f"ego{i}") for i in range(2)]
    obs: list[dict[int, Observation]] = [{}, {}]
    status: dict[str, EpisodeStatus] = {}
    for i in range(2):
        node.create_subscription(Observation, f"ego{i}/observation",
                                 lambda m, i=i: obs[i].__setitem__(time_to_ns(m.header.stamp), m), STEP)
        node.create_subscription(EpisodeStatus, f"ego{i}/episode_status",
                                 lambda m, i=i: status.__setitem__(f"ego{i}", m), 10)
    cmd = [node.create_publisher(TwistStamped, f"ego{i}/cmd", STEP) for i in range(2)]

    def answer(i: int, stamp: int, v: float, key: bytes | None = None, to: int | None = None) -> None:
        m = TwistStamped()
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(stamp, 10**9)
        m.header.frame_id = with_episode("base_link", episode_of(obs[i][stamp].header.frame_id))
        m.twist.linear.x = v
        cmd[i if to is None else to].publish(sign(keys[i] if key is None else key, m))

    def spin_until(cond, limit: float) -> bool:
        t0 = time.monotonic()
        while not cond() and time.monotonic() - t0 < limit:
            rclpy.spin_once(node, timeout_sec=0.05)
        return cond()

    graph = Graph([sim], tmp_path / "logs", env=ros_env)
    graph.start()
    log = tmp_path / "logs" / "avp_sim.log"
    try:
        # ego 0 drives off the gate (answered at once); ego 1 enters once the gate is clear
        answered: set[int] = set()
        t0 = time.monotonic()
        while not obs[1] and time.monotonic() - t0 < 120:
            rclpy.spin_once(node, timeout_sec=0.05)
            for stamp in sorted(set(obs[0]) - answered):
                answer(0, stamp, 2.0)
                answered.add(stamp)
        assert obs[1], "ego 1 never entered"
        k1 = min(obs[1])
        assert spin_until(lambda: k1 in obs[0], 10)
        answer(0, k1, 2.0)  # ego 0 answers step k1, ego 1 does not: the lot holds step k1
        assert spin_until(lambda: "from ego 1 on /avp/ego1/cmd" in log.read_text(), 30), log.read_text()[-2000:]
        assert max(obs[0]) == k1 and max(obs[1]) == k1  # nothing stepped; ego 0's observation was not re-sent
        # ego 1's key on ego 0's topic, or ego 1's command published on ego 0's: dropped, the lot still waits
        answer(1, k1, 5.0, to=0)
        answer(0, k1, 5.0, key=keys[1])
        assert spin_until(lambda: "/avp/ego0/cmd: " in log.read_text() and "unauthenticated" in log.read_text(), 30)
        time.sleep(0.5)
        rclpy.spin_once(node, timeout_sec=0.1)
        assert max(obs[0]) == k1
        answer(1, k1, 1.0)  # now ego 1 answers: the lot steps, both egos see step k1 + 1
        step = k1 + 100_000_000
        assert spin_until(lambda: step in obs[0] and step in obs[1], 30)
        assert status["ego1"].state == EpisodeStatus.STATE_RUNNING
    finally:
        graph.stop()
        node.destroy_node()
        rclpy.try_shutdown()


def test_swap_one_egos_planner_in_realtime_while_the_other_drives(ros_env, tmp_path, monkeypatch):
    """Real time, two egos, ego 1 a `reserve` ego: `avp swap-planner cautious --ego 1` replaces ego 1's planner (one
    node of its pipeline's component container) by a new process in /avp/ego1 that reads, as the one it replaced, the
    reservation node's observation (the held spots occupied), not the simulator's; ego 0's planner stays active, the
    lot keeps stepping, and the container lives on without the old planner."""
    import subprocess
    import sys

    from avp_bringup.graph import Graph, fleet_graph
    from avp_bringup.lifecycle import LifecycleClient
    from avp_monitor.monitor import EpisodeMonitor

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    nodes = fleet_graph(["bezier", "reserve"], sim_extra={"mode": "realtime", "seed": SEED, "t_final": 60.0,
                                                         "publish_markers": False, "egos.entry_interval": 2.0})
    rclpy.init()
    monitor = EpisodeMonitor()
    client = LifecycleClient(monitor)
    graph = Graph(nodes, tmp_path / "logs", env=ros_env)
    graph.start()
    swap, out = None, ""
    try:
        t0 = time.monotonic()
        while time.monotonic() - t0 < 180 and swap is None:
            rclpy.spin_once(monitor, timeout_sec=0.05)
            if len(monitor.ego_trajectory(1)) > 10:  # ego 1 is in and its pipeline answers
                swap = subprocess.Popen([sys.executable, "-m", "avp_bringup.cli", "swap-planner", "cautious",
                                         "--ego", "1", "--log-dir", str(tmp_path / "logs")], env=ros_env,
                                        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        assert swap is not None, "ego 1 never drove"
        while swap.poll() is None and time.monotonic() - t0 < 240:
            rclpy.spin_once(monitor, timeout_sec=0.05)
        out = swap.communicate(timeout=60)[0]
        k_swapped = max(monitor.gt)
        assert swap.returncode == 0, out
        assert "active planner: /avp/ego1/avp_planner_cautious" in out and "/avp/ego1/avp_planner" in out, out
        assert client.state("/avp/ego0/avp_planner") == "active"
        assert client.state("/avp/ego1/avp_planner_cautious") == "active"
        assert "observation /avp/ego1/reserved/observation" in out, out
        assert client.observation_topic("/avp/ego1/avp_planner_cautious") == "/avp/ego1/reserved/observation"
        assert client.observation_topic("/avp/ego0/avp_planner") == "/avp/ego0/observation"
        t1 = time.monotonic()
        while max(monitor.gt) < k_swapped + 20 and time.monotonic() - t1 < 60:
            rclpy.spin_once(monitor, timeout_sec=0.05)
        assert max(monitor.gt) >= k_swapped + 20, "the lot stopped stepping after the swap"
        # ego 1's old planner was unloaded from its pipeline's container; the container, its belief and
        # prediction nodes (the new planner's inputs) and ego 0's run on
        def ego1_nodes():
            return {n for n, ns in monitor.get_node_names_and_namespaces() if ns == "/avp/ego1"}

        t2 = time.monotonic()
        while "avp_planner" in ego1_nodes() and time.monotonic() - t2 < 30:
            rclpy.spin_once(monitor, timeout_sec=0.1)
        assert {"avp_belief", "avp_prediction", "avp_planner_cautious"} <= ego1_nodes(), ego1_nodes()
        assert "avp_planner" not in ego1_nodes(), ego1_nodes()
        assert graph.poll() == {"avp_sim": None, "ego0.pipeline": None, "ego1.pipeline": None, "avp_v2v": None,
                                "avp_reservation": None}, graph.poll()
    finally:
        if swap is not None and swap.poll() is None:
            swap.kill()
        import os
        import re
        import signal

        for pid in re.findall(r"\(pid (\d+),", out):  # the swapped-in planner runs detached: stop it
            try:
                os.kill(int(pid), signal.SIGINT)
            except ProcessLookupError:
                pass
        graph.stop()
        monitor.destroy_node()
        rclpy.try_shutdown()


def test_demo_of_two_egos_parks_both_and_records_both(ros_env, tmp_path, monkeypatch):
    """`avp demo --egos 2`: both egos park; the bag (read back with rosbags) holds each ego's own topics, tagged with
    its key; the GIF is written."""
    import json
    import subprocess
    import sys

    from rosbags.rosbag2 import Reader

    from avp_common.msg_auth import load_key, scoped_key, verify

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    out, bag = tmp_path / "demo", tmp_path / "bag"
    r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "demo", "--egos", "2", "--seed", str(SEED),
                        "--t-final", str(T_FINAL), "--out", str(out), "--bag", str(bag)], env=ros_env,
                       capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["state"] == "success" and [e["state"] for e in metrics["egos"]] == ["success", "success"]
    assert (out / "episode.gif").stat().st_size > 10_000 and "ego 1: success" in r.stdout
    import cv2
    import numpy as np

    from avp_viz.render import EGO_BGR
    png = cv2.imread(str(out / "episode.png")).reshape(-1, 3)
    assert all((png == np.array(c)).all(axis=1).sum() > 100 for c in EGO_BGR[:2])  # both egos drawn, each in its colour
    counts: dict[str, int] = {}
    tagged_ok = {0: 0, 1: 0}
    key = load_key()
    with Reader(bag) as reader:
        for conn, _t, raw in reader.messages():
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
            for i in (0, 1):
                if conn.topic == f"/avp/ego{i}/cmd":
                    assert verify(scoped_key(key, f"ego{i}"), raw) and not verify(scoped_key(key, f"ego{1 - i}"), raw)
                    tagged_ok[i] += 1
    for i in (0, 1):
        for t in ("observation", "cmd", "beliefs", "predictions", "decision", "episode_status"):
            assert counts.get(f"/avp/ego{i}/{t}", 0) > 0, (i, t, sorted(counts))
    assert tagged_ok[0] > 50 and tagged_ok[1] > 50
    assert counts["/avp/debug/ground_truth"] >= 300
    from avp_bag.episode import ego_metrics_from_bag
    from avp_bringup.why import explain

    for i in (0, 1):  # `avp metrics --ego i` and `avp why --ego i` read ego i's own topics
        m = ego_metrics_from_bag(bag, i)
        assert m["state"] == "success" and m["parked_spot_id"] == metrics["egos"][i]["parked_spot_id"]
        assert m["entered_step"] == (0 if i == 0 else 50)  # egos.entry_interval 5 s
        assert f"ego {i}" in explain(str(bag), ego=i).splitlines()[0]
    with pytest.raises(ValueError, match="give --ego i"):
        explain(str(bag))

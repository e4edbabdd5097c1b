"""Hostile inputs (docs/bad_input.md), tried as another process on the same DDS domain would: the reset service reads no
file it is not configured to serve and quotes no file's content; node parameters cannot be changed from outside.

Real processes over real DDS (the simulator and the planner started by avp_bringup.graph), a real rclpy client in
this process. Oracles: the process's own /proc RSS, wall-clock answer times, the simulator's ground truth.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy")

from geometry_msgs.msg import TwistStamped  # noqa: E402
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue  # noqa: E402
from rcl_interfaces.srv import GetParameters, SetParameters  # noqa: E402

from avp_bringup.graph import Graph, NodeSpec  # noqa: E402
from avp_common.conversions import step_to_time  # noqa: E402
from avp_common.msg_auth import episode_of, load_key, sign  # noqa: E402
from avp_common.qos import GROUND_TRUTH, STEP  # noqa: E402
from avp_common.services import call_idempotent  # noqa: E402
from avp_msgs.msg import GroundTruth, Observation  # noqa: E402
from avp_msgs.srv import ResetEpisode  # noqa: E402

SCENARIO = Path(__file__).resolve().parents[1] / "src/avp_sim/config/scenarios/two_cars.yaml"
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from hostile_requests import hostile_requests  # noqa: E402

REFUSED = "scenario_file: not a file of the served scenario directories"


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise AssertionError("no VmRSS")


@pytest.fixture()
def node(ros_env, monkeypatch):
    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    rclpy.init()
    n = rclpy.create_node("intruder", namespace="/avp")
    yield n, ros_env
    n.destroy_node()
    rclpy.try_shutdown()


def _call(n, client, req, timeout=60.0):
    return call_idempotent(client, req, lambda s: rclpy.spin_once(n, timeout_sec=s), timeout=timeout)


def test_reset_service_reads_only_served_scenarios(node, tmp_path):
    n, env = node
    served = tmp_path / "served"
    served.mkdir()
    (served / "broken.yaml").write_text("secret_token: hunter2\nvacant_spot_ids: [1, 2\n  - : :\n")
    outside = tmp_path / "outside.yaml"
    outside.write_text("secret_token: hunter2\n  bad: [\n")
    gts: list[GroundTruth] = []
    obs: list[Observation] = []
    n.create_subscription(GroundTruth, "debug/ground_truth", gts.append, GROUND_TRUTH)
    n.create_subscription(Observation, "observation", obs.append, STEP)
    cmd = n.create_publisher(TwistStamped, "cmd", STEP)
    # step 0 also waits for our ground-truth reader (published once a step: one sent before it matched is lost)
    spec = NodeSpec("avp_sim", "avp_sim", "sim_node", "config/sim.param.yaml",
                    {"seed": 3, "publish_markers": False, "scenario_dir": str(served), "min_debug_subscribers": 1})
    with Graph([spec], tmp_path, env=env) as g:
        client = n.create_client(ResetEpisode, "reset_episode")
        assert client.wait_for_service(timeout_sec=60)
        t0 = time.monotonic()
        while not gts and time.monotonic() - t0 < 30:
            rclpy.spin_once(n, timeout_sec=0.05)
        assert gts and gts[0].step == 0
        pid = g.procs["avp_sim"].pid
        _call(n, client, ResetEpisode.Request(seed=3, reactive=True, scenario_file="/nonexistent.yaml"))  # warm-up
        rss0 = _rss_mb(pid)
        replies = {}
        for name in ("/dev/zero", str(outside), "/etc/passwd", "/nonexistent.yaml", "../outside.yaml"):
            t = time.monotonic()
            r = _call(n, client, ResetEpisode.Request(seed=3, reactive=True, scenario_file=name))
            replies[name] = (r, time.monotonic() - t)
        for name, (r, dt) in replies.items():
            assert not r.success and REFUSED in r.message, (name, r.message)
            assert dt < 5.0, f"{name}: answered after {dt:.2f} s"
            assert "hunter2" not in r.message and "secret" not in r.message
        # the same answer whether the file exists or not: no existence oracle
        assert replies["/etc/passwd"][0].message == replies["/nonexistent.yaml"][0].message
        broken = _call(n, client, ResetEpisode.Request(seed=3, reactive=True, scenario_file="broken.yaml"))
        assert not broken.success and "scenario_file: not valid YAML (line" in broken.message
        assert "hunter2" not in broken.message and "secret" not in broken.message
        # docs/bad_input.md row 50: 10 000 vehicles (500 KB), 1 MB of YAML, a 60 000-key mapping, 5 000-deep nesting, 65
        # vehicles, NaN, aliases, ... (bench/hostile_requests.py): each refused with its reason; how fast is measured by
        # bench/bench_requests.py (docs/benchmarks.md), the limit here only shows that none stalls the simulator
        for name, (fields, needle) in hostile_requests().items():
            t = time.monotonic()
            r = _call(n, client, ResetEpisode.Request(seed=3, reactive=True, **fields))
            took = time.monotonic() - t
            assert not r.success and needle in r.message, (name, r.message)
            assert took < 5.0, f"{name}: answered after {took:.2f} s"
        assert _rss_mb(pid) - rss0 < 50.0, "the probes grew the simulator's memory"
        # the running episode is untouched: step 0 of seed 3 answers a command
        m = TwistStamped()
        m.header.stamp = step_to_time(0, 0.1)
        m.twist.linear.x = 1.0
        assert cmd.get_subscription_count() >= 1, "cmd not matched"  # ours matched the simulator's reader
        cmd.publish(sign(load_key(), m, episode_of(obs[-1].header.frame_id)))
        t0 = time.monotonic()
        while not any(x.step == 1 for x in gts) and time.monotonic() - t0 < 60:
            rclpy.spin_once(n, timeout_sec=0.05)
        assert any(x.step == 1 for x in gts)
        ok = _call(n, client, ResetEpisode.Request(seed=1, reactive=False, scenario_yaml=SCENARIO.read_text()))
        assert ok.success and ok.n_vehicles == 37
        assert g.poll()["avp_sim"] is None
    assert "Traceback" not in (tmp_path / "avp_sim.log").read_text()


def _param(name: str, value: float) -> Parameter:
    return Parameter(name=name, value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value))


def test_parameters_cannot_be_changed_from_another_process(node, tmp_path):
    n, env = node
    sim = NodeSpec("avp_sim", "avp_sim", "sim_node", "config/sim.param.yaml", {"publish_markers": False})
    planner = NodeSpec("avp_planner", "avp_planner", "planner", "config/planner.param.yaml")
    with Graph([sim, planner], tmp_path, env=env) as g:
        for node_name, key, value, good in (("avp_sim", "dt", -1.0, 0.1), ("avp_sim", "ego_max_speed", 1000.0, 5.0),
                                            ("avp_planner", "collision.vehicle_margin", -5.0, 0.3),
                                            ("avp_planner", "control.v_max", 50.0, 2.0)):
            setter = n.create_client(SetParameters, f"/avp/{node_name}/set_parameters")
            getter = n.create_client(GetParameters, f"/avp/{node_name}/get_parameters")
            assert setter.wait_for_service(timeout_sec=60) and getter.wait_for_service(timeout_sec=60)
            r = _call(n, setter, SetParameters.Request(parameters=[_param(key, value)]))
            assert len(r.results) == 1 and not r.results[0].successful, (node_name, key)
            assert key in r.results[0].reason and "read-only" in r.results[0].reason
            got = _call(n, getter, GetParameters.Request(names=[key]))
            assert got.values[0].double_value == pytest.approx(good)  # what the node runs with, unchanged
        assert all(rc is None for rc in g.poll().values())


def test_hijacked_commands_do_not_steer_the_ego(paper_lot, node, tmp_path):
    """The hijack of docs/bad_input.md row 34, as measured: a process answers every observation at once with its own
    cmd stamped like it (v = 3 m/s straight). The simulator drops the untagged commands, the episode equals the
    in-process run of the same driver bit for bit, and the simulator names the foreign publisher."""
    import numpy as np
    from test_dds_lockstep import SEED, T_FINAL, _inprocess_trajectory

    from avp_bringup.graph import default_graph, with_params
    from avp_monitor.monitor import EpisodeMonitor

    n, env = node
    expected, world, _ = _inprocess_trajectory(paper_lot, "scripted", "bezier")
    sent = []
    attacker = n.create_publisher(TwistStamped, "cmd", STEP)

    def hijack(obs: Observation) -> None:
        m = TwistStamped()
        m.header.stamp = obs.header.stamp
        m.header.frame_id = "ego"
        m.twist.linear.x = 3.0
        attacker.publish(m)
        sent.append(obs.header.stamp)

    n.create_subscription(Observation, "observation", hijack, STEP)
    nodes = default_graph("scripted")
    n_subs = nodes[0].extra_params["min_subscribers"]
    nodes[0] = with_params(nodes[0], seed=SEED, reactive=True, t_final=T_FINAL, publish_markers=False,
                           min_subscribers=n_subs + 2, min_debug_subscribers=1)  # + attacker + monitor
    monitor = EpisodeMonitor()
    with Graph(nodes, tmp_path, env=env) as g:
        t0 = time.monotonic()
        while not monitor.finished and time.monotonic() - t0 < 120:
            rclpy.spin_once(monitor, timeout_sec=0.02)
            rclpy.spin_once(n, timeout_sec=0.0)
        assert monitor.finished, "episode did not finish"
        t1 = time.monotonic()
        while len(monitor.gt) < monitor.status.step + 1 and time.monotonic() - t1 < 30:
            rclpy.spin_once(monitor, timeout_sec=0.05)
        assert all(rc is None for rc in g.poll().values())
    got = monitor.ego_trajectory()
    monitor.destroy_node()
    assert len(sent) > 10, "the attacker answered no steps"
    assert got.shape == expected.shape and np.array_equal(got, expected)  # the same episode as without it
    log = (tmp_path / "avp_sim.log").read_text()
    assert "unauthenticated message(s) dropped" in log and "/avp/intruder" in log
    # named once when it appeared (with the other publishers on cmd: Jazzy's rclpy does not say which writer sent
    # a message, so the report lists who could have), then counted at most once a second
    assert log.count("; new: [") == 1 and "'/avp/intruder'" in log.split("; new: [")[1].splitlines()[0]


def test_extreme_commands_are_clamped(node, tmp_path):
    """Commands (docs/bad_input.md row 35): v = 1e9, ω = -1e9 (tagged, so they reach the checks) move the ego at most
    ego_max_speed·dt per step with |ω| <= |v|/R_min; a stamp far in the future or negative never makes the simulator
    step; no state is ever non-finite."""
    import math

    n, env = node
    gts: list[GroundTruth] = []
    obs: list[Observation] = []
    n.create_subscription(GroundTruth, "debug/ground_truth", gts.append, GROUND_TRUTH)
    n.create_subscription(Observation, "observation", obs.append, STEP)
    cmd = n.create_publisher(TwistStamped, "cmd", STEP)
    key = load_key()

    def send(sec: int, nanosec: int, v: float, om: float) -> None:
        m = TwistStamped()
        m.header.stamp.sec, m.header.stamp.nanosec = sec, nanosec
        m.twist.linear.x, m.twist.angular.z = v, om
        spin(10, lambda: bool(obs))
        spin(30, lambda: cmd.get_subscription_count() >= 1)  # ours matched the simulator's cmd reader (volatile)
        assert cmd.get_subscription_count() >= 1, "cmd not matched"
        cmd.publish(sign(key, m, episode_of(obs[-1].header.frame_id)))  # of the running episode

    def spin(seconds: float, cond=lambda: False) -> None:
        t0 = time.monotonic()
        while not cond() and time.monotonic() - t0 < seconds:
            rclpy.spin_once(n, timeout_sec=0.02)

    spec = NodeSpec("avp_sim", "avp_sim", "sim_node", "config/sim.param.yaml",
                    {"seed": 4, "publish_markers": False, "ego_max_speed": 5.0, "min_debug_subscribers": 1})
    with Graph([spec], tmp_path, env=env) as g:
        spin(30, lambda: bool(gts))
        assert gts and gts[0].step == 0
        send(2_000_000_000, 0, 1.0, 0.0)  # far in the future
        send(-5, 0, 1.0, 0.0)  # negative
        spin(1.0)
        assert max(x.step for x in gts) == 0
        for k in range(3):
            send(0, k * 100_000_000, 1e9, -1e9)
            spin(5, lambda k=k: any(x.step == k + 1 for x in gts))
        assert g.poll()["avp_sim"] is None
    ego = [next(a for a in x.agents if a.kind == 0) for x in sorted(gts, key=lambda m: m.step)]
    assert [x.step for x in sorted(gts, key=lambda m: m.step)][:4] == [0, 1, 2, 3]
    for a, b in zip(ego, ego[1:4], strict=False):
        assert all(math.isfinite(v) for v in (b.pose.x, b.pose.y, b.pose.theta))
        assert math.hypot(b.pose.x - a.pose.x, b.pose.y - a.pose.y) <= 5.0 * 0.1 + 1e-6
        dth = math.atan2(math.sin(b.pose.theta - a.pose.theta), math.cos(b.pose.theta - a.pose.theta))
        assert abs(dth) <= 5.0 / 3.22 * 0.1 + 1e-3  # |ω| <= v_max / R_min


def test_two_demos_at_once_do_not_cross_talk(ros_env, tmp_path):
    """Cross-talk (docs/bad_input.md row 38): two `avp demo` started together without ROS_DOMAIN_ID each claim a
    domain of their own (avp_bringup.domain) and record the same episode as a lone run, bit for bit."""
    import os

    import numpy as np

    from avp_bag.episode import read_episode

    # no ROS_DOMAIN_ID: each demo claims the first domain that no graph and no test holds (the shared lock files)
    env = {k: v for k, v in ros_env.items() if k != "ROS_DOMAIN_ID"}

    def demo(tag: str) -> subprocess.Popen:
        return subprocess.Popen([sys.executable, "-m", "avp_bringup.cli", "demo", "--ego", "scripted", "--seed", "2",
                                 "--t-final", "6", "--no-gif", "--out", str(tmp_path / tag),
                                 "--bag", str(tmp_path / f"bag_{tag}")], env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True)

    runs = [demo("a"), demo("b")]
    outs = [p.communicate(timeout=240)[0] for p in runs]
    lone = demo("lone")
    outs.append(lone.communicate(timeout=240)[0])
    assert all(p.returncode == 0 for p in (*runs, lone)), outs
    domains = [next(ln for ln in o.splitlines() if "ROS_DOMAIN_ID=" in ln) for o in outs[:2]]
    assert domains[0] != domains[1], domains  # two graphs, two domains
    trajectories = []
    for tag, out in zip(("a", "b", "lone"), outs, strict=True):
        try:
            ep = read_episode(tmp_path / f"bag_{tag}")
        except ValueError as exc:  # what the demo said (a recorder that stopped or dropped messages says why)
            raise AssertionError(f"{exc}\n--- avp demo {tag}:\n{out}") from exc
        trajectories.append(np.array([[a.pose.x, a.pose.y, a.pose.theta] for g in ep["ground_truth"]
                                      for a in g.agents if a.kind == 0]))
    assert len(trajectories[2]) == 61
    assert np.array_equal(trajectories[0], trajectories[2]) and np.array_equal(trajectories[1], trajectories[2])
    assert os.path.isdir(tmp_path / "a") and os.path.isdir(tmp_path / "b")


def test_foreign_inputs_are_dropped_by_the_planner(paper_lot, ros_env, tmp_path, monkeypatch):
    """Foreign inputs (docs/bad_input.md row 41): a planner takes observation / beliefs / predictions only from holders
    of the key. An intruder's untagged inputs for a step get no command and the intruder is named; the tagged ones of
    the configured publishers (the feeder playing the simulator and the perception nodes) are answered."""
    from dataclasses import replace

    from test_bad_input import _Feeder, planner_alone

    from avp_common.conversions import step_to_ns
    from avp_msgs.msg import PredictedTrajectoryArray, SpotBeliefs
    from avp_scenario.scenario import generate_paper_scenario
    from avp_sim.core.world import World, WorldConfig

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    ns = "/authin"
    base = World(paper_lot, generate_paper_scenario(paper_lot, 3, True), WorldConfig(t_final=100.0)).observe()
    rclpy.init()
    try:
        feeder = _Feeder(paper_lot, ns)
        intruder = rclpy.create_node("intruder", namespace=ns)
        bad = {t: intruder.create_publisher(m, t, STEP) for t, m in (
            ("observation", Observation), ("beliefs", SpotBeliefs), ("predictions", PredictedTrajectoryArray))}
        graph = planner_alone(ros_env, tmp_path, ns)
        with graph:
            assert feeder.spin(30, lambda: all(feeder.node.count_subscribers(f"{ns}/{t}") > 0
                                               for t in ("observation", "beliefs", "predictions"))
                               and feeder.node.count_publishers(f"{ns}/cmd") > 0), "planner not up"
            # the planner must know the intruder (its writers matched, its node name discovered) before it can
            # name it: on a loaded machine the name can lag the match
            assert feeder.spin(30, lambda: all(bad[t].get_subscription_count() > 0 for t in bad)), "no match"
            feeder.spin(1.0)
            o, b, p = feeder.messages(replace(base, step=1))
            log_file = tmp_path / "planner_under_test.log"

            def dropped(topic: str) -> bool:  # the planner got (and dropped) an intruder's message on topic
                return f"{ns}/{topic}: 1 unauthenticated message(s)" in log_file.read_text()

            # the intruder's step 1, untagged; re-sent on a topic until the planner reports it (a writer's match is
            # not the reader's: the planner's reader may not have matched the intruder's writer yet)
            t0 = time.monotonic()
            while time.monotonic() - t0 < 30 and not all(dropped(t) for t in bad):
                for topic, msg in (("beliefs", b), ("predictions", p), ("observation", o)):
                    if not dropped(topic):
                        bad[topic].publish(msg)
                feeder.spin(2.0)
            rclpy.spin_once(intruder, timeout_sec=0.0)
            assert not any(c[0] == step_to_ns(1, base.dt) for c in feeder.cmds), "an untagged input was answered"
            # the feeder's step 2, tagged: re-sent until answered (its first messages can be lost the same way)
            assert feeder.answered(*feeder.messages(replace(base, step=2)))
        log = (tmp_path / "planner_under_test.log").read_text()
        for topic in ("observation", "beliefs", "predictions"):
            line = next(ln for ln in log.splitlines() if f"{ns}/{topic}: 1 unauthenticated message(s)" in ln)
            assert f"'{ns}/intruder'" in line, line
        intruder.destroy_node()
        feeder.node.destroy_node()
    finally:
        rclpy.try_shutdown()

"""The simulator node over real DDS: real-time watchdog, reset service, bad commands, `avp launch` + Ctrl-C."""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import time

import pytest

rclpy = pytest.importorskip("rclpy")

from geometry_msgs.msg import TwistStamped  # noqa: E402

from avp_bringup.graph import Graph, NodeSpec  # noqa: E402
from avp_common.conversions import step_to_time  # noqa: E402
from avp_common.msg_auth import episode_of, load_key, sign  # noqa: E402
from avp_common.qos import STATUS, STEP  # noqa: E402
from avp_common.services import call_idempotent, call_once  # noqa: E402
from avp_msgs.msg import EpisodeStatus, GroundTruth, Observation  # noqa: E402
from avp_msgs.srv import ResetEpisode  # noqa: E402


def _sim(extra):
    return NodeSpec("avp_sim", "avp_sim", "sim_node", "config/sim.param.yaml",
                    {"publish_markers": False, **extra})


class Probe:
    def __init__(self):
        self.node = rclpy.create_node("probe", namespace="/avp")
        self.gt: list[GroundTruth] = []
        self.status: EpisodeStatus | None = None
        self.node.create_subscription(GroundTruth, "debug/ground_truth", self.gt.append, STEP)
        self.node.create_subscription(EpisodeStatus, "episode_status", lambda m: setattr(self, "status", m), STATUS)
        self.cmd = self.node.create_publisher(TwistStamped, "cmd", STEP)
        # lock-step holds step 0 until the observation has a subscriber and cmd a publisher: we are both
        self.episode = 0  # the running episode's id, from its observations (commands must carry it)
        self.node.create_subscription(Observation, "observation",
                                      lambda m: setattr(self, "episode", episode_of(m.header.frame_id)), STEP)

    def spin_until(self, cond, timeout=60.0):
        t0 = time.monotonic()
        while not cond() and time.monotonic() - t0 < timeout:
            rclpy.spin_once(self.node, timeout_sec=0.05)
        return cond()

    def ego(self, msg):
        return next((a.pose.x, a.pose.y, a.pose.theta) for a in msg.agents if a.kind == 0)

    def send(self, step, v, om):
        m = TwistStamped()
        m.header.stamp = step_to_time(step, 0.1)
        m.twist.linear.x, m.twist.angular.z = v, om
        self.spin_until(lambda: self.episode != 0)
        # a volatile writer delivers nothing to a reader it has not matched yet: wait for ours to match the
        # simulator's cmd reader (in lock-step, the simulator's step 0 waited for its side: our cmd publisher)
        assert self.spin_until(lambda: self.cmd.get_subscription_count() >= 1), "cmd not matched"
        self.cmd.publish(sign(load_key(), m, self.episode))  # the simulator takes tagged commands of its episode


@pytest.fixture()
def ros(ros_env, monkeypatch):
    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    rclpy.init()
    probe = Probe()
    yield probe, ros_env
    probe.node.destroy_node()
    rclpy.try_shutdown()


def test_realtime_waits_for_the_first_command_then_runs(ros, tmp_path):
    """realtime_wait_first_command (default): step 0 (observation and ground truth) is re-sent until a command
    answers it, so a reader that matched late still gets it; then the world steps on the wall timer."""
    probe, env = ros
    obs_steps: list[int] = []
    probe.node.create_subscription(Observation, "observation", lambda m: obs_steps.append(int(m.step)), STEP)
    with Graph([_sim({"mode": "realtime", "seed": 1})], tmp_path, env=env) as g:
        assert probe.spin_until(lambda: len(obs_steps) >= 10 and len(probe.gt) >= 2), "step 0 is not re-sent"
        assert set(obs_steps) == {0} and {m.step for m in probe.gt} == {0}  # the clock waits at step 0
        assert len({probe.ego(m) for m in probe.gt}) == 1  # the same step 0 each time
        n_held = len(probe.gt)
        for _ in range(20):  # real time waits for no cmd publisher: re-send until the simulator's reader has it
            probe.send(0, 1.0, 0.0)  # (a copy that lands after step 0 is a step late, never applied: command_max_lag)
            if probe.spin_until(lambda: any(m.step >= 1 for m in probe.gt), timeout=2.0):
                break
        assert probe.spin_until(lambda: len(probe.gt) >= n_held + 15), "the clock did not start after the command"
        assert all(rc is None for rc in g.poll().values())
    steps = [m.step for m in probe.gt]
    k0 = steps.count(0)
    assert steps[:k0] == [0] * k0 and steps[k0:] == list(range(1, len(steps) - k0 + 1))  # then one per step
    assert probe.ego(probe.gt[k0]) != probe.ego(probe.gt[0])  # the command for step 0 moved the ego


def test_markers_are_built_for_a_subscriber(ros, tmp_path, paper_lot):
    """debug/markers (publish_markers) goes out while something subscribes: DELETEALL, every spot, the ego."""
    from visualization_msgs.msg import MarkerArray

    from avp_common.qos import DEBUG

    probe, env = ros
    got: list[MarkerArray] = []
    probe.node.create_subscription(MarkerArray, "debug/markers", got.append, DEBUG)
    with Graph([_sim({"seed": 1, "publish_markers": True})], tmp_path, env=env):
        # markers go out once per step (a lock-step re-send repeats only the observation), and only to a reader
        # matched by then: where step 0's were sent before discovery completed, hold-still commands step the
        # simulator until a step's markers arrive
        for _ in range(20):
            if probe.spin_until(lambda: len(got) >= 1, timeout=3.0):
                break
            probe.send(max((m.step for m in probe.gt), default=0), 0.0, 0.0)
        assert got, "no debug/markers with a subscriber"
    ns = [m.ns for m in got[0].markers]
    assert got[0].markers[0].action == got[0].markers[0].DELETEALL
    assert ns.count("spots") == paper_lot.n_spots and ns.count("ego") == 1


def test_realtime_without_commands_ego_holds_still(ros, tmp_path):
    probe, env = ros
    with Graph([_sim({"mode": "realtime", "seed": 1, "realtime_wait_first_command": False})], tmp_path,
               env=env) as g:
        assert probe.spin_until(lambda: len(probe.gt) >= 15), "no ground truth in real-time mode"
        assert all(rc is None for rc in g.poll().values())
    steps = [m.step for m in probe.gt]
    assert steps == sorted(steps) and steps[-1] >= 14
    poses = {probe.ego(m) for m in probe.gt}
    assert len(poses) == 1  # no command ever arrived: the ego never moved


def test_lockstep_bad_commands_are_dropped_and_node_survives(ros, tmp_path):
    probe, env = ros
    # step 0 also waits for our ground-truth reader (published once a step: one sent before it matched is lost)
    with Graph([_sim({"seed": 2, "min_debug_subscribers": 1})], tmp_path, env=env) as g:
        # wait for step 0 (needs a cmd publisher: ours) then send NaN, a future stamp, then a valid command
        assert probe.spin_until(lambda: len(probe.gt) >= 1)
        probe.send(0, math.nan, 0.0)
        probe.send(5, 1.0, 0.0)
        probe.spin_until(lambda: False, timeout=1.0)
        assert max(m.step for m in probe.gt) == 0, "a bad command made the simulator step"
        probe.send(0, 1.0, 0.0)
        assert probe.spin_until(lambda: any(m.step == 1 for m in probe.gt))
        assert all(rc is None for rc in g.poll().values())
    log = (tmp_path / "avp_sim.log").read_text()
    assert "NaN" in log and "/avp/cmd" in log


def test_reset_service(ros, tmp_path):
    probe, env = ros
    with Graph([_sim({"seed": 2, "autostart": False})], tmp_path, env=env):
        client = probe.node.create_client(ResetEpisode, "reset_episode")
        assert client.wait_for_service(timeout_sec=60)

        def call(**kw):  # re-sent while unanswered: a response can be lost while discovery settles
            return call_idempotent(client, ResetEpisode.Request(**kw),
                                   lambda s: rclpy.spin_once(probe.node, timeout_sec=s), timeout=60)

        bad = call(seed=1, reactive=True, scenario_file="/nonexistent.yaml")
        assert not bad.success and "reset_episode" in bad.message
        ok = call(seed=11, reactive=False)
        from avp_scenario.scenario import generate_paper_scenario
        from avp_world.lot import load_bundled_lot

        # the node built the same scenario as the core does for this seed (29..39 vehicles by §VI-A)
        assert ok.success and ok.n_vehicles == len(generate_paper_scenario(load_bundled_lot(), 11, False).vehicles)
        assert 29 <= ok.n_vehicles <= 39
        assert probe.spin_until(lambda: probe.status is not None and probe.status.seed == 11)
        assert not probe.status.reactive and probe.status.state == EpisodeStatus.STATE_RUNNING


def test_service_helpers_resend_or_watch_the_effect(ros):
    """A server that answers its first request too late: call_idempotent re-sends, takes the second answer and
    drops the first (its future was withdrawn); call_once never re-sends. Over real DDS."""
    import threading

    from rclpy.executors import SingleThreadedExecutor

    probe, _ = ros
    server = rclpy.create_node("slow_reset_server", namespace="/avp")
    seen: list[int] = []

    def on_reset(req, resp):
        seen.append(req.seed)
        if len(seen) == 1 or req.seed == 9:
            time.sleep(1.5)  # longer than resend_after below; seed 9: answered after its effect was seen
        resp.success, resp.n_vehicles = True, len(seen)
        return resp

    server.create_service(ResetEpisode, "slow_reset", on_reset)
    executor = SingleThreadedExecutor()
    executor.add_node(server)
    stop = threading.Event()
    thread = threading.Thread(target=lambda: [executor.spin_once(timeout_sec=0.05) for _ in iter(stop.is_set, True)])
    thread.start()
    try:
        client = probe.node.create_client(ResetEpisode, "slow_reset")
        assert client.wait_for_service(timeout_sec=60)
        spin = lambda s: rclpy.spin_once(probe.node, timeout_sec=s)  # noqa: E731
        res = call_idempotent(client, ResetEpisode.Request(seed=7), spin, timeout=60, resend_after=0.5)
        assert res is not None and res.success
        assert res.n_vehicles >= 2, "the late first answer was taken instead of a re-sent request's"
        assert seen[:2] == [7, 7]
        nobody = probe.node.create_client(ResetEpisode, "nobody")  # no server: None after the timeout
        assert call_idempotent(nobody, ResetEpisode.Request(seed=1), spin, timeout=0.5, resend_after=0.2) is None

        # call_once: sent once; an answer is taken, or the effect seen another way ends the wait (None)
        n_seen = len(seen)
        assert call_once(client, ResetEpisode.Request(seed=8), spin, lambda: False, timeout=60).success
        assert seen[n_seen:] == [8]
        t0 = time.monotonic()
        assert call_once(client, ResetEpisode.Request(seed=9), spin, lambda: time.monotonic() - t0 > 0.3) is None
        with pytest.raises(TimeoutError, match="nobody"):
            call_once(nobody, ResetEpisode.Request(seed=1), spin, lambda: False, timeout=0.3)
    finally:
        stop.set()
        thread.join()
        server.destroy_node()


def test_avp_launch_starts_graph_and_ctrl_c_stops_it(ros, tmp_path):
    probe, env = ros
    cmd = [sys.executable, "-m", "avp_bringup.cli", "launch", "--ego", "scripted", "--log-dir", str(tmp_path)]
    proc = subprocess.Popen(cmd,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert probe.spin_until(lambda: len(probe.gt) >= 5, timeout=30), "graph did not run"
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0
    assert "logs in" in out and "graph stopped" in out
    pids = [int(line.split("pid ")[1].split()[0]) for line in out.splitlines() if " pid " in line]
    assert len(pids) == 3  # simulator, scripted driver and the viewers' scene node
    assert "avp_scene: pid" in out
    for pid in pids:  # every node process is gone
        assert subprocess.run(["kill", "-0", str(pid)], capture_output=True).returncode != 0


def test_run_node_treats_errors_after_shutdown_as_shutdown(ros_env, monkeypatch):
    """avp_common.node_main.run_node: rclpy failing because the context was already shut down (what a Ctrl-C whose
    KeyboardInterrupt got swallowed leaves behind) returns 0; the same failure with the context alive propagates."""
    from avp_common.node_main import run_node

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)

    def node_that(shutdown_first: bool):
        def factory():
            node = rclpy.create_node("run_node_probe")

            def tick():
                if shutdown_first:
                    rclpy.shutdown()
                    node.create_guard_condition(lambda: None)  # rclpy's own RCLError: the context is not valid
                raise RuntimeError("a fault in a callback")

            node.create_timer(0.05, tick)
            return node
        return factory

    assert run_node(node_that(shutdown_first=True), "probe") == 0
    with pytest.raises(RuntimeError, match="a fault in a callback"):
        run_node(node_that(shutdown_first=False), "probe")


def test_ctrl_c_inside_a_finaliser_prints_nothing(monkeypatch, capsys):
    """The node processes' unraisable hook: a KeyboardInterrupt raised in a ``__del__`` (a Ctrl-C that landed
    there) prints no traceback; any other exception in a finaliser still does."""
    import gc

    from avp_common.node_main import ctrl_c_in_finaliser_hook

    class Finaliser:
        def __init__(self, exc):
            self.exc = exc

        def __del__(self):
            raise self.exc

    monkeypatch.setattr(sys, "unraisablehook", ctrl_c_in_finaliser_hook)
    Finaliser(KeyboardInterrupt())
    gc.collect()
    assert "Traceback" not in capsys.readouterr().err
    Finaliser(ValueError("a real fault"))
    gc.collect()
    err = capsys.readouterr().err
    assert "Traceback" in err and "a real fault" in err


def test_half_built_rclpy_task_after_a_stop_prints_nothing(monkeypatch, capsys):
    """Seen in CI: SIGINT under a 1 kHz flood landed inside ``rclpy.task.Task.__init__``, whose ``__del__`` then
    raised AttributeError (``_exception`` never set) and printed a traceback. Once a stop signal came, that finaliser
    prints nothing; before one came, it still does, and so does an AttributeError in a finaliser that is not rclpy's."""
    import gc

    from rclpy.task import Task

    from avp_common import node_main

    class Finaliser:
        def __del__(self):
            raise AttributeError("not rclpy")

    def half_built_task():
        task = Task.__new__(Task)  # what a KeyboardInterrupt in __init__ leaves behind: no attribute set
        del task
        gc.collect()
        return capsys.readouterr().err

    monkeypatch.setattr(sys, "unraisablehook", node_main.ctrl_c_in_finaliser_hook)
    monkeypatch.setitem(node_main._stopping, "signal", 0)
    err = half_built_task()
    assert "Traceback" in err and "_exception" in err  # no stop asked: a real fault, shown
    monkeypatch.setitem(node_main._stopping, "signal", signal.SIGINT)
    assert half_built_task() == ""
    Finaliser()
    gc.collect()
    err = capsys.readouterr().err
    assert "Traceback" in err and "not rclpy" in err



#: the graph's nodes: class, package, parameter file, extra ROS arguments; components take them as ``cli_args``, the
#: others (one process each) from ``rclpy.init``
_GRAPH_NODES = [
    ("avp_sim.sim_node:SimNode", "avp_sim", "sim.param.yaml", ["-p", "egos.count:=2", "-p", "drivers.count:=1",
                                                                 "-p", "mode:=realtime"]),
    ("avp_perception.belief_node:BeliefNode", "avp_perception", "belief.param.yaml", []),
    ("avp_perception.prediction_node:PredictionNode", "avp_perception", "prediction.param.yaml", []),
    ("avp_planner.planner_node:PlannerNode", "avp_planner", "planner.param.yaml",
     ["-p", "use_beliefs:=true", "-p", "use_predictions:=true", "-p", "use_beacons:=true"]),
    ("avp_viz.scene_node:SceneNode", "avp_viz", "scene.param.yaml", []),
    ("avp_planner.v2v_node:V2VNode", "avp_planner", "v2v.param.yaml", ["-p", "egos:=0,1"]),
    ("avp_planner.reservation_node:ReservationNode", "avp_planner", "reservation.param.yaml", ["-p", "egos:=0,1"]),
]

#: builds one node of its own process (its ROS arguments global) and prints its endpoints and QoS event handlers
_COUNT_SCRIPT = """
import importlib, sys, rclpy
from rclpy.event_handler import EventHandler
module, _, cls = sys.argv[1].partition(":")
rclpy.init(args=sys.argv[2:])
node = getattr(importlib.import_module(module), cls)()
endpoints = len(list(node.subscriptions)) + len(list(node.publishers))
print(endpoints, sum(isinstance(w, EventHandler) for w in node.waitables))
"""


def _counts(node) -> tuple[int, int]:
    """(readers + writers, QoS event handlers) of ``node``."""
    from rclpy.event_handler import EventHandler

    return (len(list(node.subscriptions)) + len(list(node.publishers)),
            sum(isinstance(w, EventHandler) for w in node.waitables))


def test_the_graphs_endpoints_have_no_qos_event_handlers(ros, tmp_path):
    """Every reader and writer of the graph's nodes and observers is made without rclpy's default QoS event handlers
    (avp_common.qos.QUIET_READER / QUIET_WRITER): each is a waitable the executor walks for every message taken. Only
    rclpy's own writer of /parameter_events, which every node has, keeps its two."""
    import importlib
    import inspect

    from avp_bag.recorder import BagRecorder, fleet_topics
    from avp_common.share import package_share
    from avp_experiment_ros.fleet_collector import FleetCollector
    from avp_monitor.monitor import EpisodeMonitor

    _, env = ros
    bare = rclpy.create_node("bare")
    _, base = _counts(bare)
    bare.destroy_node()
    assert base == 2  # rclpy's own /parameter_events writer: what every node below has
    counts: dict[str, tuple[int, int]] = {}
    nodes = []
    try:
        for component, package, params, extra in _GRAPH_NODES:
            module, _, cls = component.partition(":")
            ns = "/avp/ego0" if module.split(".")[1] in ("belief_node", "prediction_node", "planner_node",
                                                         "scene_node") else "/avp"
            args = ["--ros-args", "-r", f"__ns:={ns}", "--params-file", str(package_share(package) / "config" / params),
                    *extra]
            node_cls = getattr(importlib.import_module(module), cls)
            if any(a.kind is a.VAR_KEYWORD for a in inspect.signature(node_cls).parameters.values()):  # a component
                nodes.append(node_cls(cli_args=args, use_global_arguments=False))
                counts[cls] = _counts(nodes[-1])
            else:
                r = subprocess.run([sys.executable, "-c", _COUNT_SCRIPT, component, *args], env=env,
                                   capture_output=True, text=True, timeout=120)
                assert r.returncode == 0, r.stderr
                counts[cls] = tuple(int(x) for x in r.stdout.split()[-2:])
        nodes += [EpisodeMonitor(egos=2), BagRecorder(tmp_path / "bag", fleet_topics(2)), FleetCollector(2, None, {})]
        counts.update({type(n).__name__: _counts(n) for n in nodes[-3:]})
    finally:
        for node in nodes:
            if isinstance(node, BagRecorder):
                node.close()
            node.destroy_node()
    assert len(counts) == len(_GRAPH_NODES) + 3
    for name, (endpoints, handlers) in counts.items():
        assert endpoints > 2 and handlers == base, f"{name}: {endpoints} readers/writers, {handlers} event handlers"

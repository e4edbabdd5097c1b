"""Bad inputs (docs/bad_input.md): each gets one clear line naming the file/field/topic, and no running node
dies. Scenario files (ROS-free), start-up parameters (the real executables), messages and service
requests into running nodes over real DDS, and the `avp` command's own arguments."""

from __future__ import annotations

import copy
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from avp_scenario.scenario import ScenarioError, plan_states
from avp_sim.core.scenario_file import load_scenario_file
from avp_world.geometry import rect_corners

SCENARIO = Path(__file__).resolve().parents[1] / "src/avp_sim/config/scenarios/two_cars.yaml"


# ------------------------------------------------------------------------------------------- scenario files


def test_scenario_file_builds_what_it_says(paper_lot, tmp_path):
    from shapely.geometry import Polygon

    sc = load_scenario_file(paper_lot, SCENARIO, seed=0, reactive=False)
    data = yaml.safe_load(SCENARIO.read_text())
    assert sc.seed == 7 and sc.reactive  # the file's values win over the request's
    assert np.allclose(sc.ego_start, data["ego_start"])
    parked = {v.id: v for v in sc.vehicles if v.parked}
    assert set(parked) == {s.id for s in paper_lot.spots} - set(data["vacant_spot_ids"])
    for s in paper_lot.spots:  # a parked car on the centre of every other spot, along the spot's axis
        if s.id in parked:
            x, y, th = parked[s.id].initial_state
            assert (x, y) == pytest.approx((s.x, s.y)) and math.cos(th - s.heading) == pytest.approx(
                math.copysign(1.0, math.cos(th - s.heading)))
    dyn = sc.dynamic_vehicles()
    assert [(v.target_spot_id, v.maneuver, v.passiveness) for v in dyn] == [
        (d["target_spot"], d["maneuver"], d["passiveness"]) for d in data["dynamic_vehicles"]]
    for v in dyn:  # the plan ends parked inside its target spot (shapely as the oracle)
        end = plan_states(v)[-1]
        spot = next(s for s in paper_lot.spots if s.id == v.target_spot_id)
        spot_poly = Polygon(rect_corners(np.array([spot.x, spot.y, spot.heading]), spot.length, spot.width))
        assert spot_poly.buffer(1e-6).contains(Polygon(rect_corners(end, v.length, v.width)))
    assert all(v.passiveness == 0 for v in load_scenario_file(
        paper_lot, _scenario_file(tmp_path, lambda d: d.pop("reactive")), 0, False).dynamic_vehicles())


def _scenario_file(tmp: Path, mutate) -> Path:
    data = yaml.safe_load(SCENARIO.read_text())
    mutate(data)
    p = tmp / f"scenario_{abs(hash(str(data)))}.yaml"
    p.write_text(yaml.safe_dump(data) if not isinstance(data, str) else data)
    return p


SCENARIO_CASES = [
    ("unknown spot id", lambda d: d["vacant_spot_ids"].append(99), "vacant_spot_ids[5]: unknown spot id 99"),
    ("unknown maneuver", lambda d: d["dynamic_vehicles"][0].__setitem__("maneuver", "near/before/sideways"),
     "dynamic_vehicles[0].maneuver"),
    ("target not vacant", lambda d: d["dynamic_vehicles"][1].__setitem__("target_spot", 30),
     "dynamic_vehicles[1].target_spot: spot 30 is not in vacant_spot_ids"),
    ("wrong type", lambda d: d["dynamic_vehicles"][0].__setitem__("cruise_speed", "fast"),
     "dynamic_vehicles[0].cruise_speed: expected a finite number"),
    ("out of range", lambda d: d["dynamic_vehicles"][0].__setitem__("passiveness", -2),
     "dynamic_vehicles[0].passiveness: -2 is outside"),
    ("missing key", lambda d: d.pop("vacant_spot_ids"), "vacant_spot_ids: missing"),
    ("unknown key", lambda d: d.__setitem__("pedestrians", []), "'pedestrians': unknown key"),
    ("ego outside the lot", lambda d: d.__setitem__("ego_start", [-50.0, 0.0, 0.0]), "ego_start"),
]


@pytest.mark.parametrize("name,mutate,needle", SCENARIO_CASES, ids=[c[0] for c in SCENARIO_CASES])
def test_bad_scenario_files(paper_lot, tmp_path, name, mutate, needle):
    path = _scenario_file(tmp_path, mutate)
    with pytest.raises(ScenarioError) as exc:
        load_scenario_file(paper_lot, path, 0, True)
    msg = str(exc.value)
    assert needle in msg and str(path) in msg and "\n" not in msg


def test_scenario_file_not_yaml_or_missing(paper_lot, tmp_path):
    bad = tmp_path / "s.yaml"
    bad.write_text("vacant_spot_ids: [1, 2\n  - : :")
    with pytest.raises(ScenarioError, match="not valid YAML") as exc:
        load_scenario_file(paper_lot, bad, 0, True)
    assert "\n" not in str(exc.value)
    with pytest.raises(ScenarioError, match="no such scenario file"):
        load_scenario_file(paper_lot, tmp_path / "nope.yaml", 0, True)


# ------------------------------------------------------------------------------------------- start-up

rclpy = pytest.importorskip("rclpy")

from avp_bringup.graph import Graph, NodeSpec  # noqa: E402
from avp_common.services import call_idempotent  # noqa: E402


def _sim(**extra) -> NodeSpec:
    return NodeSpec("avp_sim", "avp_sim", "sim_node", "config/sim.param.yaml", extra)


_PLANNER = NodeSpec("avp_planner", "avp_planner", "planner", "config/planner.param.yaml")
DROP = object()
STARTUP_CASES = [  # (case, node, key in its parameter file, value (DROP: remove the key), the one line says)
    ("sim dt out of range", _sim(), "dt", -0.1, "parameter 'dt': -0.1 is below the minimum 0.01"),
    ("sim n_ray not an integer", _sim(), "sensor.n_ray", 3.5, "parameter 'sensor.n_ray': expected an integer"),
    ("sim missing key", _sim(), "t_final", DROP, "parameter 't_final': missing"),
    ("sim too many egos", _sim(), "egos.count", 9, "parameter 'egos.count': 9 is above the maximum 8"),
    ("sim malformed lot map", _sim(), "lot_file", "BADLOT", "lot.yaml: spots[id=0]: spot lies (partly) outside"),
    ("planner bad type", _PLANNER, "search.max_iterations", "many",
     "parameter 'search.max_iterations': expected an integer"),
    ("planner told with no source", _PLANNER, "collision.reactive_evidence", "told",
     "parameter collision.reactive_evidence: 'told' is for an in-process caller"),
]


@pytest.mark.parametrize("name,spec,key,value,needle", STARTUP_CASES, ids=[c[0] for c in STARTUP_CASES])
def test_bad_parameters_stop_the_node_at_start_up_with_one_line(ros_env, tmp_path, name, spec, key, value, needle):
    if value == "BADLOT":
        from avp_world.lot import bundled_lot_path

        lot = yaml.safe_load(bundled_lot_path().read_text())
        lot["spot_rows"][0]["first_center"] = [1.0, 8.375]  # outside the boundary
        value = str(tmp_path / "lot.yaml")
        Path(value).write_text(yaml.safe_dump(lot))
    data = yaml.safe_load(spec.default_params().read_text())
    node = data["/**"]["ros__parameters"]
    *parents, leaf = key.split(".")
    for k in parents:
        node = node[k]
    if value is DROP:
        del node[leaf]
    else:
        node[leaf] = value
    params = tmp_path / "p.yaml"
    params.write_text(yaml.safe_dump(data))
    cmd = Graph([spec], tmp_path, None).command(spec)
    cmd[cmd.index("--params-file") + 1] = str(params)
    r = subprocess.run(cmd, env=ros_env, capture_output=True, text=True, timeout=60)
    out = (r.stdout + r.stderr).strip()
    lines = [ln for ln in out.splitlines() if "start-up failed" in ln]
    assert r.returncode == 2 and len(lines) == 1, out
    assert needle in lines[0] and "Traceback" not in out, out


# ------------------------------------------------------------------------------------------- runtime, planner


class _Feeder:
    """Plays the simulator and the perception nodes for a planner running alone (its own namespace)."""

    def __init__(self, lot, ns: str):
        from geometry_msgs.msg import TwistStamped

        from avp_common.conversions import lot_to_msg
        from avp_common.qos import LATCHED, STEP
        from avp_msgs.msg import LotMap, Observation, PredictedTrajectoryArray, SpotBeliefs

        self.node = rclpy.create_node("feeder", namespace=ns)
        self.lot = lot
        self.cmds: list[int] = []
        from avp_common.msg_auth import Authenticator

        auth = Authenticator(self.node)  # a holder of the key: what it sends tests the checks behind the tag
        self.pub_lot = auth.publisher(LotMap, "lot_map", LATCHED)
        self.pub_obs = auth.publisher(Observation, "observation", STEP)
        self.pub_bel = auth.publisher(SpotBeliefs, "beliefs", STEP)
        self.pub_pred = auth.publisher(PredictedTrajectoryArray, "predictions", STEP)
        self.node.create_subscription(TwistStamped, "cmd", self._on_cmd, STEP)
        self.lot_msg = lot_to_msg(lot)
        self.pub_lot.publish(self.lot_msg)

    def _on_cmd(self, msg) -> None:
        from avp_common.conversions import time_to_ns

        self.cmds.append((time_to_ns(msg.header.stamp), msg.twist.linear.x, msg.twist.angular.z))

    def spin(self, seconds: float, until=None) -> bool:
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds:
            rclpy.spin_once(self.node, timeout_sec=0.05)
            if until is not None and until():
                return True
        return until is None or until()

    def answered(self, o, b, p, timeout: float = 60.0, resend_after: float = 3.0) -> bool:
        """Publish a step's beliefs, predictions and observation, again every ``resend_after`` s (as the simulator
        re-sends a step) until its command comes; False after ``timeout`` s. For the first step after the planner
        came up: the graph counts say its endpoints exist, not that each reader (the planner's of our inputs, ours
        of cmd) has matched its writer, and a volatile writer drops what it wrote before. The planner takes a copy
        of a pending step's input once and answers a copy of the step it answered with the same command."""
        from avp_common.conversions import time_to_ns

        want = time_to_ns(o.header.stamp)
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout:
            self.pub_bel.publish(b)
            self.pub_pred.publish(p)
            self.pub_obs.publish(o)
            if self.spin(min(resend_after, timeout - (time.monotonic() - t0)),
                         lambda: any(c[0] == want for c in self.cmds)):
                return True
        return False

    def messages(self, obs):
        from avp_common.conversions import beliefs_to_msg, observation_to_msg, predictions_to_msg

        b = np.full(self.lot.n_spots, 0.5, dtype=np.float32)
        return (observation_to_msg(obs), beliefs_to_msg(obs.step, obs.dt, self.lot.spot_ids, b),
                predictions_to_msg(obs.step, obs.dt, []))


def planner_alone(ros_env: dict, tmp_path: Path, ns: str) -> Graph:
    """A graph of one planner node (beliefs and predictions on) in namespace ``ns``, logging to
    ``tmp_path/planner_under_test.log``; not started."""
    spec = NodeSpec("planner_under_test", "avp_planner", "planner", "config/planner.param.yaml",
                    {"use_beliefs": True, "use_predictions": True})
    graph = Graph([spec], tmp_path, env=ros_env)
    cmd = graph.command(spec)
    cmd[cmd.index("__ns:=/avp")] = f"__ns:={ns}"
    graph.command = lambda s: cmd
    return graph


def _bad_obs(field):
    def mutate(o, b, p):
        if field == "nan_pose":
            o.ego_pose.x = math.nan
        elif field == "empty_history":
            o.vehicles[0].history = []
        elif field == "oversized_unknown_ids":
            o.vacant_spot_ids = list(range(1000, 6000))
        elif field == "beliefs_range":
            b.beliefs[3] = 1.5
        elif field == "beliefs_unknown_id":
            b.spot_ids[0] = 999
        elif field == "beliefs_size":
            b.beliefs = np.zeros(len(b.spot_ids) + 1, dtype=np.float32)
        elif field == "pred_nan":
            p.trajectories[0].poses[2].y = math.inf
        elif field == "pred_dt":
            p.trajectories[0].dt = 0.0
        return o, b, p
    return mutate


PLANNER_CASES = [  # (case, mutation, the planner log must contain)
    ("observation with NaN ego pose", "nan_pose", "/observation step {k}: ego_pose: contains NaN or inf"),
    ("observed vehicle with an empty history", "empty_history", "/observation step {k}: vehicle"),
    ("observation with 5000 unknown spot ids", "oversized_unknown_ids",
     "/observation step {k}: invalid input: unknown spot id 1000"),
    ("belief outside [0, 1]", "beliefs_range", "/beliefs step {k}: beliefs must lie in [0, 1]"),
    ("belief for an unknown spot id", "beliefs_unknown_id", "/beliefs step {k}: unknown spot id 999"),
    ("more beliefs than spot ids", "beliefs_size", "/beliefs step {k}: 40 spot ids but 41 beliefs"),
    ("predicted pose with inf", "pred_nan", "/predictions step {k}: prediction of agent"),
    ("prediction with dt = 0", "pred_dt", "/predictions step {k}: prediction of agent 1000: dt must be > 0"),
]


def test_bad_messages_into_a_running_planner(ros_env, tmp_path, monkeypatch, paper_lot):
    """Each bad message: one error line naming topic and step, a hold-still command (v = ω = 0) for that
    step, and the planner keeps answering the next good step."""
    from dataclasses import replace

    from lifecycle_msgs.srv import ChangeState

    from avp_common.conversions import step_to_ns
    from avp_msgs.msg import PredictedTrajectory
    from avp_scenario.scenario import generate_paper_scenario
    from avp_sim.core.world import World, WorldConfig

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    ns = "/badin"
    world = World(paper_lot, generate_paper_scenario(paper_lot, 3, True), WorldConfig(t_final=100.0))
    while not any(not v.is_static for v in world.observe().vehicles):  # until a dynamic vehicle is seen
        world.step(1.0, 0.0)
    base = world.observe()
    rclpy.init()
    feeder = _Feeder(paper_lot, ns)
    graph = planner_alone(ros_env, tmp_path, ns)
    graph.start()
    log = tmp_path / "planner_under_test.log"
    try:
        # every input matched (a step's message published before its reader matched would be lost) and cmd
        assert feeder.spin(30, lambda: all(feeder.node.count_subscribers(f"{ns}/{t}") > 0
                                           for t in ("observation", "beliefs", "predictions"))
                           and feeder.node.count_publishers(f"{ns}/cmd") > 0), "planner not up"

        def play(step: int, mutate=None, resend=False):
            o, b, p = feeder.messages(replace(base, step=step))
            if mutate is not None:
                pred = PredictedTrajectory(agent_id=1000, dt=0.1, probability=1.0)
                from geometry_msgs.msg import Pose2D

                pred.poses = [Pose2D(x=1.0 + i, y=2.0, theta=0.0) for i in range(5)]
                p.trajectories = [pred]
                o, b, p = mutate(o, b, p)
            want = step_to_ns(step, base.dt)
            if resend:
                assert feeder.answered(o, b, p), f"no command for step {step}"
            else:
                feeder.pub_bel.publish(b)
                feeder.pub_pred.publish(p)
                feeder.pub_obs.publish(o)
                assert feeder.spin(30, lambda: any(c[0] == want for c in feeder.cmds)), f"no command for step {step}"
            return next(c for c in feeder.cmds if c[0] == want)

        play(1, resend=True)  # a good step first, re-sent until answered: every input and cmd matched both ways
        step = 2
        for _name, field, needle in PLANNER_CASES:
            c = play(step, _bad_obs(field))
            assert c[1:] == (0.0, 0.0), (field, c)
            text = log.read_text()
            assert needle.format(k=step) in text, (field, text[-2000:])
            play(step + 1)  # ... and the next good step is answered
            step += 2
        # observation stamps out of order: an older step is dropped with a warning (no command)
        o, b, p = feeder.messages(replace(base, step=5))
        n = len(feeder.cmds)
        feeder.pub_bel.publish(b)
        feeder.pub_pred.publish(p)
        feeder.pub_obs.publish(o)
        feeder.spin(1.5)
        assert len(feeder.cmds) == n
        assert f"step 5 is older than step {step - 1} (out of order); dropped" in log.read_text()
        # a lot map with NaN: rejected, the planner keeps the lot it has
        bad_lot = copy.deepcopy(feeder.lot_msg)
        bad_lot.spots[0].pose.x = math.nan
        feeder.pub_lot.publish(bad_lot)
        feeder.spin(1.0)
        assert "lot_map:" in log.read_text()
        play(step)
        # an impossible lifecycle transition (configure while active): answered with success = false
        client = feeder.node.create_client(ChangeState, f"{ns}/planner_under_test/change_state")
        assert client.wait_for_service(timeout_sec=60)
        req = ChangeState.Request()
        req.transition.id = 1
        # re-sent while unanswered (the new client's response reader may not be matched by the planner yet, which
        # then drops the answer: avp_common/services.py); each request the planner gets is refused with one line
        n_sent = 0
        for _ in range(10):
            fut = client.call_async(req)
            n_sent += 1
            if feeder.spin(3.0, fut.done):
                break
            client.remove_pending_request(fut)
        assert fut.done() and fut.result().success is False
        n_refused = log.read_text().count("is not possible from state 'active'")
        assert 1 <= n_refused <= n_sent, (n_refused, n_sent)
        play(step + 1)
        assert graph.poll()["planner_under_test"] is None
    finally:
        graph.stop()
        feeder.node.destroy_node()
        rclpy.try_shutdown()
    lines = [ln for ln in log.read_text().splitlines()
             if ("[ERROR]" in ln or "[WARN]" in ln) and "planner_under_test]" in ln]
    # one line per case (and per refused change_state request, counted above)
    assert len(lines) == len(PLANNER_CASES) + 2 + n_refused, lines
    assert "Traceback" not in log.read_text()


# ------------------------------------------------------------------------------------------- runtime, simulator


def test_bad_requests_into_a_running_simulator(ros_env, tmp_path, monkeypatch):
    """cmd with NaN / inf / a stamp ahead of the step, reset with a missing or malformed scenario file:
    one line each, the simulator does not step on them and keeps running; a valid scenario file works."""
    from geometry_msgs.msg import TwistStamped

    from avp_common.conversions import step_to_time
    from avp_common.msg_auth import episode_of, load_key, sign
    from avp_common.qos import STATUS, STEP
    from avp_msgs.msg import EpisodeStatus, GroundTruth, Observation
    from avp_msgs.srv import ResetEpisode

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    rclpy.init()
    node = rclpy.create_node("probe", namespace="/avp")
    gts, status = [], []
    node.create_subscription(GroundTruth, "debug/ground_truth", gts.append, STEP)
    node.create_subscription(EpisodeStatus, "episode_status", status.append, STATUS)
    obs = []
    node.create_subscription(Observation, "observation", obs.append, STEP)
    pub = node.create_publisher(TwistStamped, "cmd", STEP)
    client = node.create_client(ResetEpisode, "reset_episode")

    def spin(seconds, until=None):
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds and not (until and until()):
            rclpy.spin_once(node, timeout_sec=0.05)

    def send(step, v, om):
        m = TwistStamped()
        m.header.stamp = step_to_time(step, 0.1)
        m.twist.linear.x, m.twist.angular.z = v, om
        spin(10, lambda: bool(obs))
        spin(30, lambda: pub.get_subscription_count() >= 1)  # ours matched the simulator's cmd reader (volatile)
        assert pub.get_subscription_count() >= 1, "cmd not matched"
        pub.publish(sign(load_key(), m, episode_of(obs[-1].header.frame_id)))  # tagged, of the running episode

    def reset(**kw):  # re-sent while unanswered: a response can be lost while discovery settles
        return call_idempotent(client, ResetEpisode.Request(**kw), lambda s: rclpy.spin_once(node, timeout_sec=s),
                               timeout=60)

    bad_scenario = tmp_path / "bad.yaml"
    data = yaml.safe_load(SCENARIO.read_text())
    data["dynamic_vehicles"][0]["target_spot"] = 30
    bad_scenario.write_text(yaml.safe_dump(data))
    # step 0 also waits for our ground-truth reader (published once a step: one sent before it matched is lost)
    graph = Graph([_sim(seed=2, publish_markers=False, scenario_dir=str(tmp_path), min_debug_subscribers=1)],
                  tmp_path, env=ros_env)
    graph.start()
    try:
        spin(30, lambda: len(gts) >= 1)
        assert gts, "no step 0"
        send(0, math.nan, 0.0)
        send(0, 1.0, math.inf)
        send(7, 1.0, 0.0)
        spin(1.0)
        assert max(g.step for g in gts) == 0, "a bad command made the simulator step"
        assert client.wait_for_service(timeout_sec=60)
        r1 = reset(seed=1, reactive=True, scenario_file=str(tmp_path / "nope.yaml"))
        r2 = reset(seed=1, reactive=True, scenario_file=str(bad_scenario))
        assert not r1.success and "scenario_file: not a file of the served" in r1.message and "\n" not in r1.message
        assert not r2.success and "dynamic_vehicles[0].target_spot" in r2.message and "\n" not in r2.message
        two = dict(yaml.safe_load(SCENARIO.read_text()), egos=[{"start": [21.5, 38.0, -1.5708], "enter_at": 5.0}])
        r3 = reset(seed=1, reactive=True, scenario_yaml=yaml.safe_dump(two))  # 2 egos for a simulator of 1
        assert not r3.success and "egos: 2 egos, but this simulator drives 1 (parameter egos.count)" in r3.message, \
            r3.message
        send(0, 1.0, 0.0)  # the episode that was running is untouched by the failed resets
        spin(10, lambda: any(g.step == 1 for g in gts))
        assert any(g.step == 1 for g in gts)
        ok = reset(seed=1, reactive=False, scenario_file=SCENARIO.name)  # a bundled scenario, by name
        assert ok.success and ok.n_vehicles == 37
        spin(10, lambda: status and status[-1].seed == 7)
        assert status[-1].seed == 7 and status[-1].reactive  # the file's seed and reactive flag
        assert graph.poll()["avp_sim"] is None
    finally:
        graph.stop()
        node.destroy_node()
        rclpy.try_shutdown()
    text = (tmp_path / "avp_sim.log").read_text()
    assert "/avp/cmd: command with NaN/inf (v=nan, omega=0.0) dropped" in text
    assert "/avp/cmd: command with NaN/inf (v=1.0, omega=inf) dropped" in text
    assert "/avp/cmd: command stamped 700000000 ns is ahead of step 0; dropped" in text
    assert "reset_episode: " in text and "Traceback" not in text


# ------------------------------------------------------------------------------------------- the avp command


def test_bad_command_line_inputs(ros_env, tmp_path):
    def avp(*args):
        r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", *args], env=ros_env, capture_output=True,
                           text=True, timeout=60)
        return r.returncode, r.stderr.strip()

    (tmp_path / "exists").mkdir()
    rc, err = avp("record", str(tmp_path / "exists"), "--duration", "0.1")
    assert rc == 2 and err == f"[avp record] {tmp_path / 'exists'} exists already, not overwriting"
    rc, err = avp("replay", str(tmp_path / "nope"))
    assert rc == 2 and len(err.splitlines()) == 1 and "nope" in err
    rc, err = avp("metrics", str(tmp_path))
    assert rc == 2 and len(err.splitlines()) == 1 and "metadata" in err
    rc, err = avp("swap-planner", "no_such_profile")
    assert rc == 2 and len(err.splitlines()) == 1 and "unknown planner profile 'no_such_profile'" in err
    bad = tmp_path / "bad_profile.yaml"
    bad.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"control": {"v_maxx": 1.0}}}}))
    rc, err = avp("swap-planner", str(bad))
    assert rc == 2 and err == f"[avp swap-planner] {bad.resolve()}: parameter 'control.v_maxx': unknown key"


def test_a_planner_behind_in_real_time_skips_to_the_newest_step(ros_env, tmp_path, monkeypatch, paper_lot):
    """Found by the busy DLP benchmark: in real time, a step whose newer observation is already waiting
    is skipped (its command would be ignored by the simulator) and logged; the newer step is answered. In lock-step
    the same arrival order is answered step by step."""
    from dataclasses import replace

    from avp_common.conversions import step_to_ns
    from avp_common.qos import STATUS
    from avp_msgs.msg import EpisodeStatus
    from avp_scenario.scenario import generate_paper_scenario
    from avp_sim.core.world import World, WorldConfig

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    ns = "/behind"
    base = World(paper_lot, generate_paper_scenario(paper_lot, 3, True), WorldConfig(t_final=100.0)).observe()
    rclpy.init()
    feeder = _Feeder(paper_lot, ns)
    pub_status = feeder.node.create_publisher(EpisodeStatus, "episode_status", STATUS)
    graph = planner_alone(ros_env, tmp_path, ns)
    graph.start()
    log = tmp_path / "planner_under_test.log"
    try:
        assert feeder.spin(30, lambda: all(feeder.node.count_subscribers(f"{ns}/{t}") > 0
                                           for t in ("observation", "beliefs", "predictions", "episode_status"))
                           and feeder.node.count_publishers(f"{ns}/cmd") > 0), "planner not up"

        def behind(first: int) -> set[int]:
            """Observations of steps first and first + 1 arrive before step first's beliefs and predictions."""
            msgs = [feeder.messages(replace(base, step=s)) for s in (first, first + 1)]
            for o, _, _ in msgs:
                feeder.pub_obs.publish(o)
            feeder.spin(0.5)
            for _, b, p in msgs:
                feeder.pub_bel.publish(b)
                feeder.pub_pred.publish(p)
            want = step_to_ns(first + 1, base.dt)
            assert feeder.spin(30, lambda: any(c[0] == want for c in feeder.cmds)), "no command for the newer step"
            feeder.spin(0.5)
            return {c[0] for c in feeder.cmds}

        # step 0 first, re-sent until answered: every input and cmd matched both ways before the arrival order counts
        assert feeder.answered(*feeder.messages(replace(base, step=0))), "no command for step 0"
        answered = behind(1)  # lock-step (no episode_status yet): both steps decided
        assert step_to_ns(1, base.dt) in answered
        status = EpisodeStatus(lock_step=False, state=EpisodeStatus.STATE_RUNNING)
        pub_status.publish(status)
        feeder.spin(1.0)
        answered = behind(10)  # real time: step 10 skipped, step 11 answered
        assert step_to_ns(10, base.dt) not in answered and step_to_ns(11, base.dt) in answered
        assert "step 10 skipped, a newer observation is waiting (real time" in log.read_text()
    finally:
        graph.stop()
        feeder.node.destroy_node()
        rclpy.try_shutdown()

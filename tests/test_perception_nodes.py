"""The belief and prediction nodes over real DDS, in real processes.

A probe node in this process publishes the lot map and a sequence of observations of a simulated episode
and receives beliefs, intentions, predictions, debug/bev (Image) and debug/occupancy (OccupancyGrid).
Oracles: the perception cores run here in-process on the same observations (PerceptionCore, the
predictors), with the float32 rounding of the message fields written out here; the occupancy grid is
rebuilt cell by cell with shapely polygons; the BEV tiles are compared with the core's images.
Bad inputs (NaN, unknown spot ids, stamps that do not match, time going back) must give one error line
naming the topic, no output for that message, and the node keeps answering.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from nav_msgs.msg import OccupancyGrid  # noqa: E402
from sensor_msgs.msg import Image  # noqa: E402

from avp_bringup.graph import Graph, NodeSpec  # noqa: E402
from avp_common.conversions import (  # noqa: E402
    lot_to_msg,
    observation_from_msg,
    observation_to_msg,
    predictions_from_msg,
    step_to_time,
)
from avp_common.msg_auth import with_episode  # noqa: E402
from avp_common.qos import LATCHED, STEP  # noqa: E402
from avp_msgs.msg import (  # noqa: E402
    IntentionArray,
    LotMap,
    Observation,
    PredictedTrajectory,
    PredictedTrajectoryArray,
    SpotBeliefs,
)
from avp_perception.conversions import intentions_to_msg  # noqa: E402
from avp_predictors.intention import Intention  # noqa: E402

BELIEF = NodeSpec("avp_belief", "avp_perception", "belief_node", "config/belief.param.yaml")
PREDICTION = NodeSpec("avp_prediction", "avp_perception", "prediction_node", "config/prediction.param.yaml")
N_STEPS = 25


def f32(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float32).astype(float)


# ----------------------------------------------------------------------------------------- references


def _share(pkg: str, rel: str) -> str:
    from ament_index_python.packages import get_package_share_directory

    return f"{get_package_share_directory(pkg)}/{rel}"


def node_params():
    from avp_common.params import load_yaml_params
    from avp_perception.params import BELIEF_PARAMS, PREDICTION_PARAMS

    b = load_yaml_params(_share("avp_perception", "config/belief.param.yaml"), "avp_belief", BELIEF_PARAMS)
    r = load_yaml_params(_share("avp_perception", "config/prediction.param.yaml"), "avp_prediction",
                         PREDICTION_PARAMS)
    return b, r


def reference_core(lot, b):
    """The belief node's core, built here from the shipped parameter values."""
    import torch

    from avp_perception.core.pipeline import PerceptionCore, make_intent_predictor
    from avp_perception.params import bev_config

    torch.set_num_threads(b["torch_threads"])
    cfg = bev_config(b)
    intent, _ = make_intent_predictor(lot, cfg, b["intent.weights"], b["intent.seed"], b["intent.mode"])
    return PerceptionCore(lot, cfg, intent=intent, t_hist=b["t_hist"], belief_init=b["belief_init"], keep_bevs=True)


def rounded(it: Intention) -> Intention:
    """The intention as it travels in the message (float32 probabilities), written out independently."""
    return replace(it, spot_probabilities=f32(it.spot_probabilities),
                   exploration_probabilities=f32(it.exploration_probabilities),
                   none_probability=float(np.float32(it.none_probability)))


_EPISODES: dict = {}


def episode_observations(lot, method: str):
    """Cached :func:`_episode_observations`."""
    if method not in _EPISODES:
        _EPISODES[method] = _episode_observations(lot, method)
    return _EPISODES[method]


def _episode_observations(lot, method: str):
    """Observations of N_STEPS consecutive steps of the first seeded episode (ego parked mid-lot, two dynamic
    vehicles) in which the in-process pipeline conditions some prediction on an intention >= mu, and the
    in-process outputs per step: (observations, [(beliefs, intentions, predictions, bevs)])."""
    from avp_perception.params import prediction_config
    from avp_predictors.prediction import make_predictor
    from avp_scenario.scenario import ScenarioError, ScenarioParams, generate_paper_scenario
    from avp_sim.core.world import World

    b, r = node_params()
    params = replace(ScenarioParams(), ego_start=(21.5, 20.0, -math.pi / 2), n_dynamic=(2, 2))
    for seed in range(60):
        try:
            world = World(lot, generate_paper_scenario(lot, seed, True, params))
        except ScenarioError:
            continue
        obs = []
        for _ in range(N_STEPS):
            obs.append(observation_from_msg(observation_to_msg(world.observe())))  # as the node receives it
            world.step(0.0, 0.0)
        core = reference_core(lot, b)
        predictor = make_predictor(method, lot, prediction_config(r))
        ref = []
        for o in obs:
            out = core.perceive(o)
            preds = predictor.predict(o, [rounded(i) for i in out.intentions])
            ref.append((out.beliefs, out.intentions, preds, out.bevs))
        if sum(p.goal is not None for _, _, preds, _ in ref for p in preds) >= 5:
            return obs, ref
    raise AssertionError("no seed gives conditioned predictions")


# ---------------------------------------------------------------------------------------------- probe


class Probe:
    def __init__(self, lot):
        self.node = rclpy.create_node("perception_probe", namespace="/avp")
        self.got: dict[str, dict[int, list]] = {k: {} for k in ("beliefs", "intentions", "predictions", "bev",
                                                                  "occupancy")}
        from avp_common.msg_auth import Authenticator

        auth = Authenticator(self.node)  # plays the simulator and the belief node: tags what it sends
        self.pub_lot = auth.publisher(LotMap, "lot_map", LATCHED)
        self.pub_obs = auth.publisher(Observation, "observation", STEP)
        self.pub_int = auth.publisher(IntentionArray, "intentions", STEP)
        for name, typ, topic in (("beliefs", SpotBeliefs, "beliefs"), ("intentions", IntentionArray, "intentions"),
                                 ("predictions", PredictedTrajectoryArray, "predictions")):
            self.node.create_subscription(typ, topic, self._store(name, lambda m: int(m.step)), STEP)
        stamp_step = lambda m: round((m.header.stamp.sec * 10**9 + m.header.stamp.nanosec) / 1e8)  # noqa: E731
        self.node.create_subscription(Image, "debug/bev", self._store("bev", stamp_step), STEP)
        self.node.create_subscription(OccupancyGrid, "debug/occupancy", self._store("occupancy", stamp_step), STEP)
        self.pub_lot.publish(lot_to_msg(lot))

    def _store(self, name, key):
        def cb(msg):
            # the message tag (avp_common.msg_auth) covers the bytes sent, CDR padding included: a re-sent answer
            # carries another tag; the content is what is compared
            msg.header.frame_id = msg.header.frame_id.partition("#")[0]
            self.got[name].setdefault(key(msg), []).append(msg)
        return cb

    def spin_until(self, cond, timeout=30.0) -> bool:
        t0 = time.monotonic()
        while not cond() and time.monotonic() - t0 < timeout:
            rclpy.spin_once(self.node, timeout_sec=0.02)
        return cond()

    def spin_for(self, seconds: float) -> None:
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds:
            rclpy.spin_once(self.node, timeout_sec=0.02)

    def wait_for_graph(self, n_obs_subs: int, topics=("beliefs",)) -> None:
        ok = self.spin_until(lambda: self.pub_obs.get_subscription_count() >= n_obs_subs and all(
            self.node.count_publishers(f"/avp/{t}") >= 1 for t in topics), 30.0)
        assert ok, "perception nodes not discovered"
        self.spin_for(0.5)

    def step(self, msg: Observation, need=("beliefs", "intentions", "predictions"), count=1, resend=()) -> bool:
        """Publish an observation and wait for its outputs; re-send (as the simulator does) if one is missing.
        ``resend``: (publisher, message) pairs published again with it each time (another input of the step)."""
        k = int(msg.step)
        for _ in range(4):
            for pub, m in resend:
                pub.publish(m)
            self.pub_obs.publish(msg)
            if self.spin_until(lambda: all(len(self.got[n].get(k, [])) >= count for n in need), 10.0):
                return True
        return False


@pytest.fixture()
def ros(ros_unbuffered):
    return ros_unbuffered  # tests/conftest.py


def log_lines(tmp_path, name: str, level: str) -> list[str]:
    return [ln for ln in (tmp_path / "logs" / f"{name}.log").read_text().splitlines() if f"[{level}]" in ln]


# ----------------------------------------------------------------------------------------------- tests


def check_occupancy(msg: OccupancyGrid, lot, beliefs: np.ndarray, seen: np.ndarray) -> None:
    """Every cell against shapely: spot cells round(100 b) once observed else -1, lot 0, outside 100."""
    import shapely
    from shapely.geometry import Polygon

    info = msg.info
    assert info.resolution == pytest.approx(0.25) and msg.header.frame_id == "map"
    assert (info.origin.position.x, info.origin.position.y) == (0.0, 0.0)
    assert (info.width, info.height) == (math.ceil(43.0 / 0.25), math.ceil(41.5 / 0.25))
    xs = (np.arange(info.width) + 0.5) * info.resolution
    ys = (np.arange(info.height) + 0.5) * info.resolution
    gx, gy = np.meshgrid(xs, ys)
    expect = np.where(shapely.contains_xy(Polygon(lot.boundary), gx, gy), 0, 100)
    for i, corners in enumerate(lot.spot_corners):
        inside = shapely.contains_xy(Polygon(corners), gx, gy)
        expect[inside] = round(100 * beliefs[i]) if seen[i] else -1
    np.testing.assert_array_equal(np.asarray(msg.data, dtype=int).reshape(info.height, info.width), expect)


@pytest.mark.parametrize("method", ["bezier", "hybrid_astar", "learned"])
def test_nodes_over_dds_match_the_cores(paper_lot, ros, tmp_path, method):
    lot = paper_lot
    obs, ref = episode_observations(lot, method)
    probe = Probe(lot)
    graph = Graph([BELIEF, NodeSpec(PREDICTION.name, PREDICTION.package, PREDICTION.executable,
                                    PREDICTION.param_file, {"method": method})], tmp_path / "logs", env=ros)
    graph.start()
    try:
        probe.wait_for_graph(2, ("beliefs", "intentions", "predictions"))
        for k, o in enumerate(obs):
            assert probe.step(observation_to_msg(o), ("beliefs", "intentions", "predictions", "bev", "occupancy")), (
                f"no output for step {k}")
            if k == 3:  # a re-sent observation is answered with the same messages, not a second update
                probe.step(observation_to_msg(o), count=2)
        assert all(rc is None for rc in graph.poll().values())
    finally:
        graph.stop()
        probe.node.destroy_node()
    b, _ = node_params()
    seen = np.zeros(lot.n_spots, dtype=bool)
    n_cond = 0
    for k, (o, (beliefs, intentions, preds, bevs)) in enumerate(zip(obs, ref, strict=True)):
        seen[[lot.spot_index(s) for s in (*o.vacant_spot_ids, *o.occupied_spot_ids)]] = True
        # beliefs: every spot of the lot, b_t of eq. (8) in float32
        (bm,) = probe.got["beliefs"][k][:1]
        assert list(bm.spot_ids) == lot.spot_ids.tolist()
        np.testing.assert_array_equal(np.asarray(bm.beliefs, dtype=float), f32(beliefs))
        # intentions
        im = probe.got["intentions"][k][0]
        assert [m.vehicle_id for m in im.intentions] == [it.vehicle_id for it in intentions]
        for m, it in zip(im.intentions, intentions, strict=True):
            assert list(m.spot_ids) == it.spot_ids.tolist()
            np.testing.assert_array_equal(np.asarray(m.spot_probabilities, dtype=float), f32(it.spot_probabilities))
            np.testing.assert_array_equal(np.array([[q.x, q.y, q.theta] for q in m.exploration_points]).reshape(-1, 3),
                                          it.exploration_points)
            np.testing.assert_array_equal(np.asarray(m.exploration_probabilities, dtype=float),
                                          f32(it.exploration_probabilities))
            assert m.none_probability == np.float32(it.none_probability)
        # predictions: same trajectories, poses bit for bit, each carrying its intention
        pm = probe.got["predictions"][k][0]
        got = predictions_from_msg(pm)
        assert len(got) == len(preds)
        for g, p, m in zip(got, preds, pm.trajectories, strict=True):
            assert (g.agent_id, g.spot_id, g.is_pedestrian) == (p.agent_id, p.spot_id, p.is_pedestrian)
            assert g.probability == np.float32(p.probability)
            np.testing.assert_array_equal(g.poses, p.poses)
            kind = (PredictedTrajectory.INTENT_SPOT if p.spot_id >= 0 else PredictedTrajectory.INTENT_EXPLORE
                    if p.goal is not None else PredictedTrajectory.INTENT_NONE)
            assert m.intention_kind == kind
            if p.goal is not None:
                np.testing.assert_array_equal(g.goal, p.goal)
                n_cond += 1
        # debug/bev: the BEVs I_k,0 side by side (2 white columns between)
        img = probe.got["bev"][k][0]
        size = b["bev.size_px"]
        assert (img.encoding, img.height, img.step) == ("rgb8", size, 3 * img.width)
        arr = np.frombuffer(bytes(img.data), dtype=np.uint8).reshape(img.height, img.width, 3)
        if bevs:
            assert img.width == len(bevs) * size + 2 * (len(bevs) - 1)
            for j, bev in enumerate(bevs):
                np.testing.assert_array_equal(arr[:, j * (size + 2): j * (size + 2) + size], bev.image)
        else:
            assert img.width == size and not arr.any()
        # debug/occupancy
        check_occupancy(probe.got["occupancy"][k][0], lot, beliefs, seen)
    assert n_cond >= 5
    # the re-sent observation of step 3: the same messages again
    for name in ("beliefs", "intentions", "predictions"):
        first, again = probe.got[name][3][:2]
        assert first == again


@pytest.mark.parametrize("source,ego_intent", [("observation", True), ("nawaz", False)])
def test_belief_sources_and_ego_intention_over_dds(paper_lot, ros, tmp_path, source, ego_intent):
    """belief_source observation (eq. 7 only; Table I 'Implicit') with the ego's own intention, and nawaz (Nawaz
    et al.'s occupancy from constant-velocity predictions), against the cores called here one by one: eq. (7)
    written out by hand, NawazOccupancy on the 4 s constant-velocity predictions of the prediction module (the
    node predicts only the 2.5 s the rule samples), ego_intention on an ego history kept here."""
    from avp_belief_map.belief import BeliefMap
    from avp_perception.core.nawaz import NawazOccupancy
    from avp_predictors.implicit import ego_intention
    from avp_predictors.prediction import ConstantVelocityPredictor

    lot = paper_lot
    obs, _ = episode_observations(lot, "bezier")
    probe = Probe(lot)
    ego_msgs = probe.got["ego_intention"] = {}  # waited for with the step's other outputs (re-sent if missing)
    probe.node.create_subscription(IntentionArray, "ego_intention",
                                   probe._store("ego_intention", lambda m: int(m.step)), STEP)
    graph = Graph([NodeSpec(BELIEF.name, BELIEF.package, BELIEF.executable, BELIEF.param_file,
                            {"belief_source": source, "ego_intent": ego_intent, "debug.bev": "never",
                             "debug.occupancy": "never"})], tmp_path / "logs", env=ros)
    graph.start()
    need = ("beliefs", "intentions", "ego_intention") if ego_intent else ("beliefs", "intentions")
    try:
        probe.wait_for_graph(1, need)
        for k, o in enumerate(obs):
            assert probe.step(observation_to_msg(o), need), f"no output for step {k}"
        assert all(rc is None for rc in graph.poll().values())
    finally:
        graph.stop()
        probe.node.destroy_node()
    b_par, _ = node_params()
    intent = reference_core(lot, b_par).intent if ego_intent else None
    beliefs = BeliefMap.from_lot(lot, b_par["belief_init"])
    b7 = np.full(lot.n_spots, b_par["belief_init"])
    hist: list[np.ndarray] = []
    keep = round(b_par["t_hist"] / obs[0].dt) + 1
    n_changed = 0
    for k, o in enumerate(obs):
        b7[[lot.spot_index(i) for i in o.vacant_spot_ids]] = 0.0  # eq. (7) by hand
        b7[[lot.spot_index(i) for i in o.occupied_spot_ids]] = 1.0
        beliefs.observe(o.vacant_spot_ids, o.occupied_spot_ids)
        expect = b7.copy()
        if source == "nawaz":
            expect = NawazOccupancy(lot).update(beliefs, o, ConstantVelocityPredictor(lot).predict(o))
            n_changed += int(np.any(expect != b7))
        got = probe.got["beliefs"][k][0]
        np.testing.assert_array_equal(np.asarray(got.beliefs, dtype=float), f32(expect))
        assert probe.got["intentions"][k][0].intentions == []  # nobody else's intention with these sources
        hist = (hist + [np.asarray(o.ego_pose, dtype=float)])[-keep:]
        if ego_intent:
            ref = ego_intention(intent, o, beliefs, np.array(hist))
            (m,) = ego_msgs[k][0].intentions
            assert m.vehicle_id == 0 and list(m.spot_ids) == ref.spot_ids.tolist()
            np.testing.assert_array_equal(np.asarray(m.spot_probabilities, dtype=float), f32(ref.spot_probabilities))
            assert m.none_probability == np.float32(ref.none_probability)
        else:
            assert ego_msgs == {}
    if source == "nawaz":
        assert n_changed >= 5  # the dynamic vehicles' predictions raise some vacant spot above eq. (7)'s 0


def test_belief_node_bad_observations(paper_lot, ros, tmp_path):
    lot = paper_lot
    obs, ref = episode_observations(lot, "bezier")
    probe = Probe(lot)
    graph = Graph([NodeSpec(BELIEF.name, BELIEF.package, BELIEF.executable, BELIEF.param_file,
                            {"debug.bev": "never"})], tmp_path / "logs", env=ros)
    graph.start()
    need = ("beliefs", "intentions")
    try:
        probe.wait_for_graph(1, need)
        assert probe.step(observation_to_msg(obs[0]), need)
        bad = []
        m = observation_to_msg(obs[1])
        m.ego_pose.x = float("nan")
        bad.append((m, "ego_pose: contains NaN"))
        m = observation_to_msg(replace(obs[1], vacant_spot_ids=np.append(obs[1].vacant_spot_ids, 999)))
        bad.append((m, "vacant_spot_ids: unknown spot id 999"))
        m = observation_to_msg(obs[1])
        m.header.stamp = step_to_time(2, 0.1)
        bad.append((m, "does not match step 1"))
        for m, _ in bad:
            probe.pub_obs.publish(m)
        probe.spin_for(1.5)
        assert 1 not in probe.got["beliefs"], "a bad observation was answered"
        assert probe.step(observation_to_msg(obs[1]), need)  # the node keeps going, its state untouched
        np.testing.assert_array_equal(np.asarray(probe.got["beliefs"][1][0].beliefs, dtype=float), f32(ref[1][0]))
        # a replayed copy of the running episode's step 0: dropped, no reset
        probe.pub_obs.publish(observation_to_msg(obs[0]))
        probe.spin_for(1.0)
        assert len(probe.got["beliefs"][0]) == 1, "a replayed step 0 was answered"
        # a later episode id (a new episode): a reset, and the answer of a fresh core
        other = replace(obs[5], step=0)
        new_episode = observation_to_msg(other)
        new_episode.header.frame_id = with_episode("map", 1)
        assert probe.step(new_episode, need, count=2)
        # ... after which a message of the earlier episode is a replay: dropped
        probe.pub_obs.publish(observation_to_msg(replace(obs[6], step=1)))
        probe.spin_for(1.0)
        assert len(probe.got["beliefs"][1]) == 1, "a message of an earlier episode was answered"
        fresh = reference_core(lot, node_params()[0]).perceive(other)
        np.testing.assert_array_equal(np.asarray(probe.got["beliefs"][0][1].beliefs, dtype=float),
                                      f32(fresh.beliefs))
        assert probe.got["bev"] == {}  # debug.bev: never
        assert all(rc is None for rc in graph.poll().values())
    finally:
        graph.stop()
        probe.node.destroy_node()
    errors = log_lines(tmp_path, "avp_belief", "ERROR")
    assert len(errors) == len(bad), errors
    for line, (_, needle) in zip(errors, bad, strict=True):
        assert "/avp/observation step 1" in line and needle in line and "dropped" in line
    warns = log_lines(tmp_path, "avp_belief", "WARN")
    assert len(warns) == 2 and all("/avp/observation" in w for w in warns), warns
    assert "step 0 is older than step 1" in warns[0] and "a replay of an earlier episode" in warns[1]


def test_prediction_node_bad_intentions(paper_lot, ros, tmp_path):
    lot = paper_lot
    obs, ref = episode_observations(lot, "bezier")
    probe = Probe(lot)
    graph = Graph([PREDICTION], tmp_path / "logs", env=ros)
    graph.start()
    need = ("predictions",)

    def messages(k: int, its, stamp_step: int | None = None, obs_step: int | None = None, episode: int = 0):
        o = replace(obs[k], step=k if obs_step is None else obs_step)
        m = intentions_to_msg(o.step, o.dt, its)
        m.header.frame_id = with_episode("map", episode)
        if stamp_step is not None:
            m.header.stamp = step_to_time(stamp_step, o.dt)
        om = observation_to_msg(o)
        om.header.frame_id = with_episode("map", episode)
        return m, om

    def send(*args, **kw):
        m, om = messages(*args, **kw)
        probe.pub_int.publish(m)
        return om

    try:
        assert probe.spin_until(lambda: probe.pub_obs.get_subscription_count() >= 1
                                and probe.pub_int.get_subscription_count() >= 1
                                and probe.node.count_publishers("/avp/predictions") >= 1, 30.0)
        probe.spin_for(0.5)
        good = [rounded(i) for i in ref[0][1]]
        # step 0's intentions are re-sent with its observation (the node's reader of ours may not have matched yet,
        # and the node waits for both; a copy of an answered step's intentions is ignored)
        int0, obs0 = messages(0, good)
        assert probe.step(obs0, need, resend=[(probe.pub_int, int0)])
        vid = ref[0][1][0].vehicle_id if ref[0][1] else 1000
        nan = Intention(vid, np.array([lot.spot_ids[0]]), np.array([np.nan]), none_probability=0.5)
        unknown = Intention(vid, np.array([999]), np.array([0.5]), none_probability=0.5)
        bad = [(send(1, [nan]), "spot_probabilities: contains NaN"),
               (send(2, [unknown]), "unknown spot id 999"),
               (send(3, good, stamp_step=4), "differs from the observation's")]
        size = intentions_to_msg(4, 0.1, [Intention(vid, np.array([lot.spot_ids[0]]), np.array([0.5]),
                                                    none_probability=0.5)])
        size.intentions[0].spot_probabilities = np.array([0.5, 0.2], dtype=np.float32)
        probe.pub_int.publish(size)
        bad.append((observation_to_msg(replace(obs[4], step=4)), "1 spot ids but 2 probabilities"))
        for m, _ in bad:
            probe.pub_obs.publish(m)
        probe.spin_for(1.5)
        assert set(probe.got["predictions"]) == {0}, "a bad message was answered"
        assert probe.step(send(5, [rounded(i) for i in ref[5][1]]), need)  # still running
        # a replayed step 0 of the running episode is dropped; a later episode's step 0 is answered
        probe.pub_obs.publish(send(0, good))
        probe.spin_for(1.0)
        assert len(probe.got["predictions"][0]) == 1, "a replayed step 0 was answered"
        assert probe.step(send(6, [rounded(i) for i in ref[6][1]], obs_step=0, episode=1), need, count=2)
        assert all(rc is None for rc in graph.poll().values())
    finally:
        graph.stop()
        probe.node.destroy_node()
    errors = log_lines(tmp_path, "avp_prediction", "ERROR")
    assert len(errors) == len(bad), errors
    for k, (line, (_, needle)) in enumerate(zip(errors, bad, strict=True), start=1):
        assert f"/avp/intentions step {k}" in line and needle in line and "dropped" in line
    warns = log_lines(tmp_path, "avp_prediction", "WARN")
    assert len(warns) == 1 and "step 0 is older than step 5" in warns[0], warns


def test_launch_file_starts_the_default_graph():
    """launch/avp.launch.py (not runnable here: no `launch` package) lists the nodes of default_graph."""
    import ast
    from pathlib import Path

    from avp_bringup.graph import default_graph

    src = Path(__file__).resolve().parents[1] / "src/avp_bringup/launch/avp.launch.py"
    tree = ast.parse(src.read_text())
    nodes = next(ast.literal_eval(n.value) for n in tree.body if isinstance(n, ast.Assign)
                 and getattr(n.targets[0], "id", "") == "NODES")
    graph = default_graph("planner")
    assert [(p, e, n, f"config/{y}", x) for p, e, n, y, x in nodes] == [
        (s.package, s.executable, s.name, s.param_file, s.extra_params) for s in graph]

"""The tracker node over real DDS (avp_tracking.tracker_node): bad detection messages refused one by one while the
node keeps tracking; a scripted DetectedObjects publisher as a real detector; `avp demo --sensing realistic`."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from std_msgs.msg import Header  # noqa: E402

from avp_bringup.graph import TRACKER_NODE, Graph, with_params  # noqa: E402
from avp_common.conversions import lot_to_msg, observation_to_msg, step_to_time  # noqa: E402
from avp_common.detection_msgs import detections_to_msg  # noqa: E402
from avp_common.qos import LATCHED, STEP  # noqa: E402
from avp_msgs.msg import LotMap, Observation  # noqa: E402
from avp_world.detections import VehicleDetection  # noqa: E402
from avp_world.types import Observation as CoreObservation  # noqa: E402

CLI = [sys.executable, "-m", "avp_bringup.cli"]


@pytest.fixture()
def ros(ros_unbuffered):
    return ros_unbuffered  # tests/conftest.py


def _frame(step: int) -> Observation:
    """A frame of the simulator's noisy sensing: the ego's pose, no vehicles."""
    core = CoreObservation(step=step, dt=0.1, ego_pose=np.array([2.0, 2.0, 0.0]), ego_length=4.5, ego_width=1.9,
                           ego_speed=0.0, vacant_spot_ids=np.zeros(0, np.int64),
                           occupied_spot_ids=np.zeros(0, np.int64), ray_ranges=np.full(8, 5.0, np.float32),
                           ray_angle_increment=2 * math.pi / 8)
    return observation_to_msg(core, "map")


def _car(x: float, y: float) -> VehicleDetection:
    return VehicleDetection(pose=np.array([x, y, 0.0]), length=4.5, width=1.9,
                            covariance=np.diag([0.01, 0.01, 0.003]), speed=0.0, speed_variance=0.07)


class Probe:
    """Plays the simulator (tagged frames and lot map) and a detector (DetectedObjects, untagged or tagged)."""

    def __init__(self, lot, signed_detections: bool):
        from autoware_perception_msgs.msg import DetectedObjects

        from avp_common.msg_auth import Authenticator

        self.node = rclpy.create_node("tracker_probe", namespace="/avp")
        auth = Authenticator(self.node)
        self.pub_lot = auth.publisher(LotMap, "lot_map", LATCHED)
        self.pub_frame = auth.publisher(Observation, "sensing/observation", STEP)
        self.pub_det = (auth.publisher(DetectedObjects, "sensing/detections", STEP) if signed_detections
                        else self.node.create_publisher(DetectedObjects, "sensing/detections", STEP))
        self.got: dict[int, Observation] = {}
        self.node.create_subscription(Observation, "observation", lambda m: self.got.__setitem__(int(m.step), m),
                                      STEP)
        self.pub_lot.publish(lot_to_msg(lot))

    def spin_until(self, cond, timeout=30.0) -> bool:
        t0 = time.monotonic()
        while not cond() and time.monotonic() - t0 < timeout:
            rclpy.spin_once(self.node, timeout_sec=0.02)
        return cond()

    def detections(self, step: int, cars, frame_id: str = "map"):
        return detections_to_msg(cars, [], Header(stamp=step_to_time(step, 0.1), frame_id=frame_id))


def test_bad_detection_messages_are_refused_and_the_node_keeps_tracking(paper_lot, ros, tmp_path):
    """NaN and infinite poses, a negative size, too many objects and another frame: each message refused with one
    error naming the topic and the field; the steps go on (answered without them) and the car of the good messages
    keeps one track."""
    probe = Probe(paper_lot, signed_detections=False)
    spec = with_params(TRACKER_NODE, min_subscribers=1, auth_detections=False, detection_wait=0.3,
                       max_objects=50)
    graph = Graph([spec], tmp_path / "logs", env=ros)
    graph.start()
    try:
        assert probe.spin_until(lambda: probe.pub_frame.get_subscription_count() >= 1
                                and probe.node.count_publishers("/avp/observation") >= 1), "tracker not up"
        probe.spin_until(lambda: False, 1.0)
        bad = []
        m = probe.detections(0, [_car(5.0, 5.0)])
        m.objects[0].kinematics.pose_with_covariance.pose.position.x = float("nan")
        bad.append((m, "objects[0]: kinematics.pose_with_covariance.pose.position holds nan: must be finite"))
        m = probe.detections(0, [_car(5.0, 5.0)])
        m.objects[0].kinematics.pose_with_covariance.covariance[7] = float("inf")
        bad.append((m, "objects[0]: kinematics.pose_with_covariance.covariance holds inf: must be finite"))
        m = probe.detections(0, [_car(5.0, 5.0)])
        m.objects[0].shape.dimensions.x = -1.0
        bad.append((m, "objects[0]: shape.dimensions (length -1.0"))
        bad.append((probe.detections(0, [_car(5.0 + i, 5.0) for i in range(51)]), "objects: 51 objects, at most 50"))
        bad.append((probe.detections(0, [_car(5.0, 5.0)], frame_id="base_link"),
                    "header.frame_id 'base_link': detections must be in the 'map' frame"))
        for step in range(0, 12):
            if step < len(bad):  # the bad message of this step, then the frame: answered without detections
                probe.pub_det.publish(bad[step][0])
            else:
                probe.pub_det.publish(probe.detections(step, [_car(5.0, 5.0)]))
            probe.spin_until(lambda: False, 0.05)
            probe.pub_frame.publish(_frame(step))
            assert probe.spin_until(lambda s=step: s in probe.got, 15.0), f"step {step} not answered"
        assert all(not probe.got[k].vehicles for k in range(len(bad))), "a refused message made a track"
        ids = {v.id for k in range(len(bad) + 3, 12) for v in probe.got[k].vehicles}
        assert len(ids) == 1 and all(len(probe.got[k].vehicles) == 1 for k in range(len(bad) + 3, 12))
        assert all(rc is None for rc in graph.poll().values())
    finally:
        graph.stop()
        probe.node.destroy_node()
    errors = [ln for ln in (tmp_path / "logs" / "avp_tracker.log").read_text().splitlines() if "[ERROR]" in ln]
    assert len(errors) == len(bad), errors
    for line, (_, needle) in zip(errors, bad, strict=True):
        assert "/avp/sensing/detections" in line and needle in line and "dropped" in line, (line, needle)


def test_a_scripted_detector_feeds_the_tracks_the_planner_reads(paper_lot, ros, tmp_path):
    """A graph whose tracker reads a scripted DetectedObjects publisher (a real detector's place: remapped topic,
    untagged, its own clock; the simulator's own detections reach nothing): the scripted car becomes a track on the
    observation the planner reads, and the planner answers those steps."""
    from avp_bringup.graph import ego_graph, with_sensing

    nodes = with_sensing(ego_graph("bezier"), "realistic")
    i = next(j for j, n in enumerate(nodes) if n.name == "avp_tracker")
    nodes[i] = replace(with_params(nodes[i], auth_detections=False, sync="latest", max_detection_age=1.0),
                       remaps=(("sensing/detections", "/my_detector/objects"),))
    code = ("import time, rclpy, numpy as np\nfrom std_msgs.msg import Header\n"
            "from autoware_perception_msgs.msg import DetectedObjects\n"
            "from avp_common.detection_msgs import detections_to_msg\n"
            "from avp_world.detections import VehicleDetection\n"
            "rclpy.init(); n = rclpy.create_node('scripted_detector')\n"
            "pub = n.create_publisher(DetectedObjects, '/my_detector/objects', 10)\n"
            "car = VehicleDetection(pose=np.array([20.0, 14.0, 0.0]), length=4.5, width=1.9, "
            "covariance=np.diag([0.01, 0.01, 0.003]), speed=0.0, speed_variance=0.07)\n"
            "while rclpy.ok():\n"
            "    pub.publish(detections_to_msg([car], [], Header(frame_id='map')))\n"
            "    rclpy.spin_once(n, timeout_sec=0.05)\n")
    ros_env = ros
    detector = subprocess.Popen([sys.executable, "-c", code], env=ros_env)
    probe = rclpy.create_node("scripted_probe", namespace="/avp")
    from avp_msgs.msg import PlannerDecision

    seen: dict[int, list] = {}
    decided: set[int] = set()
    probe.create_subscription(Observation, "observation",
                              lambda m: seen.__setitem__(int(m.step), [(v.history[-1].x, v.history[-1].y)
                                                                        for v in m.vehicles]), STEP)
    probe.create_subscription(PlannerDecision, "decision", lambda m: decided.add(int(m.step)), STEP)
    graph = Graph(nodes, tmp_path / "logs", env=ros_env)
    graph.start()
    try:
        t0 = time.monotonic()
        while time.monotonic() - t0 < 120 and not any(k >= 20 for k in decided):
            rclpy.spin_once(probe, timeout_sec=0.05)
            assert all(rc is None for rc in graph.poll().values()), graph.poll()
        with_car = [k for k, cars in seen.items() if any(math.hypot(x - 20.0, y - 14.0) < 0.5 for x, y in cars)]
        assert with_car, f"no track of the scripted car in {len(seen)} observations"
        assert all(len(cars) <= 1 for cars in seen.values()), "the simulator's own detections reached the tracker"
        assert set(with_car) & decided, "the planner answered none of the steps with the scripted track"
    finally:
        graph.stop()
        detector.kill()
        probe.destroy_node()


def test_sensing_demo_parks_its_bag_holds_no_simulator_history_and_replays(ros_env, tmp_path):
    """`avp demo --sensing realistic` on seed 1 parks; its bag holds the raw detections and the tracks; no vehicle
    pose the ego received equals a true one (no exact history); the ego's trajectory equals the in-process
    episode's bit for bit (same seed, same noise, over DDS or not); metrics recomputed from the bag equal the live
    ones; the bag replays; the ego's pose comes with the localiser's covariance."""
    from rosbags.highlevel import AnyReader

    from avp_bag.typestore import make_typestore

    out, bag = tmp_path / "demo", tmp_path / "bag"
    r = subprocess.run([*CLI, "demo", "--seed", "1", "--sensing", "realistic", "--no-gif", "--out", str(out),
                        "--bag", str(bag), "--timeout", "300"], env=ros_env, capture_output=True, text=True,
                       timeout=400)
    assert r.returncode == 0, r.stdout + r.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["state"] == "success", metrics
    with AnyReader([Path(bag)], default_typestore=make_typestore()) as reader:
        topics = {c.topic: c for c in reader.connections}
        for t in ("/avp/sensing/observation", "/avp/sensing/detections", "/avp/tracking/objects"):
            assert t in topics, t

        def read(t):
            return [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(connections=[topics[t]])]

        frames, obs, gts, tracks = (read(t) for t in ("/avp/sensing/observation", "/avp/observation",
                                                      "/avp/debug/ground_truth", "/avp/tracking/objects"))
    # every step's frame (a re-sent one, under load, twice), none with a vehicle or a pedestrian in it
    assert {int(f.step) for f in frames} == set(range(metrics["steps"]))
    assert all(not f.vehicles and not f.pedestrians for f in frames)
    assert sum(len(m.objects) for m in tracks) > 0
    # the localiser's covariance crosses the graph, from the simulator's frame to the observation the planner reads
    assert all(np.asarray(m.ego_pose_covariance).reshape(3, 3)[0, 0] > 0 for m in (*frames, *obs))
    true_poses = {(round(a.pose.x, 9), round(a.pose.y, 9)) for g in gts for a in g.agents}
    received = [(round(v.history[-1].x, 9), round(v.history[-1].y, 9)) for m in obs for v in m.vehicles]
    assert received and not (set(received) & true_poses), "a vehicle pose the ego received is the true one"
    from avp_episode.episodes import run_episode_inproc
    from avp_episode.run_config import RunConfig, run_profile, sim_values
    from avp_sim.core.factory import load_lot_param
    from avp_world.lot import load_bundled_lot

    cfg = RunConfig(sim_overrides={"sensing.model": "realistic"})
    sim = sim_values(cfg)
    lot = load_lot_param(sim["lot_file"])
    assert lot.name == load_bundled_lot().name
    poses: list = []
    run_episode_inproc(lot, sim, run_profile("bezier", cfg), 1, True, cfg,
                       on_step=lambda w, _: poses.append(w.log_ego[-1].copy()))
    live = np.array([[a.pose.x, a.pose.y, a.pose.theta] for g in gts for a in g.agents if a.kind == 0])[1:]
    assert live.shape == np.array(poses).shape and np.array_equal(live, np.array(poses))
    m = subprocess.run([*CLI, "metrics", str(bag)], env=ros_env, capture_output=True, text=True, timeout=120)
    assert m.returncode == 0 and "recomputed metrics equal the live ones" in m.stdout + m.stderr, m.stdout + m.stderr
    rp = subprocess.run([*CLI, "replay", str(bag), "--rate", "20"], env=ros_env, capture_output=True, text=True,
                        timeout=120)
    assert rp.returncode == 0, rp.stdout + rp.stderr

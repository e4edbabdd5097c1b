"""`avp demo` end to end over DDS: metrics.json, episode.png, an MCAP bag that rosbags' reader decodes,
and `avp metrics BAG` recomputing the live metrics from the bag's ground truth."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import pytest

pytest.importorskip("rclpy")


def test_demo_writes_results_and_a_readable_bag(ros_env, tmp_path):
    from rosbags.highlevel import AnyReader

    out, bag = tmp_path / "demo", tmp_path / "bag"
    r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "demo", "--seed", "4", "--t-final", "4",
                        "--out", str(out), "--bag", str(bag), "--timeout", "120"], env=ros_env,
                       capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stdout + r.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["seed"] == 4 and metrics["state"] in ("timeout", "success", "collision")
    assert metrics["steps"] == 40 or metrics["state"] != "timeout"
    img = cv2.imread(str(out / "episode.png"))
    assert img is not None and img.shape[0] > 400 and img.shape[1] > 400
    # independent reader: rosbags' AnyReader builds the types from the definitions stored in the bag
    with AnyReader([Path(bag)]) as reader:
        topics = {c.topic: c for c in reader.connections}
        for t in ("/avp/lot_map", "/avp/observation", "/avp/cmd", "/avp/debug/ground_truth", "/clock"):
            assert t in topics, t
        gts = [reader.deserialize(raw, c.msgtype) for c, _, raw in
               reader.messages(connections=[topics["/avp/debug/ground_truth"]])]
        lots = [reader.deserialize(raw, c.msgtype) for c, _, raw in
                reader.messages(connections=[topics["/avp/lot_map"]])]
        decisions = [reader.deserialize(raw, c.msgtype) for c, _, raw in
                     reader.messages(connections=[topics["/avp/decision"]])]
    # the planner node answered every step with a decision carrying its timings and plan
    assert [d.step for d in decisions] == list(range(metrics["steps"]))
    assert all(d.mode in (0, 1, 2) and d.path_planning_time >= 0.0 for d in decisions)
    assert any(d.mode != 0 and len(d.plan.poses) >= 2 for d in decisions)
    assert [g.step for g in gts] == list(range(metrics["steps"] + 1))  # every step recorded, in order
    assert len(lots) == 1 and len(lots[0].spots) == 40
    assert topics["/avp/lot_map"].ext.offered_qos_profiles[0].durability.name == "TRANSIENT_LOCAL"
    m = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "metrics", str(bag)], env=ros_env,
                       capture_output=True, text=True, timeout=60)
    assert m.returncode == 0, m.stdout + m.stderr
    assert "equal the live ones" in m.stdout


EXAMPLE = Path(__file__).resolve().parents[1] / "bags" / "examples" / "demo_seed4_4s"


def test_replay_republishes_the_recorded_bytes(ros_env, monkeypatch):
    import time

    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rosbags.highlevel import AnyReader

    from avp_common.qos import LATCHED
    from avp_msgs.msg import LotMap, Observation

    with AnyReader([EXAMPLE]) as reader:
        conn = next(c for c in reader.connections if c.topic == "/avp/observation")
        expected = [bytes(raw) for _, _, raw in reader.messages(connections=[conn])]
    assert len(expected) >= 30
    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    rclpy.init()
    node = rclpy.create_node("replay_probe")
    got, lots = [], []
    deep = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)  # rate 0 floods: keep everything
    node.create_subscription(Observation, "/avp/observation", got.append, deep, raw=True)
    node.create_subscription(LotMap, "/avp/lot_map", lots.append, LATCHED, raw=True)
    proc = subprocess.Popen([sys.executable, "-m", "avp_bringup.cli", "replay", str(EXAMPLE), "--rate", "0",
                             "--delay", "3", "--topics", "/avp/observation", "/avp/lot_map"], env=ros_env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        t0 = time.monotonic()
        while len(got) < len(expected) and time.monotonic() - t0 < 30:
            rclpy.spin_once(node, timeout_sec=0.05)
        out, _ = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
        node.destroy_node()
        rclpy.try_shutdown()
    assert proc.returncode == 0, out
    assert [bytes(g) for g in got] == expected  # same messages, same order, byte for byte
    assert len(lots) == 1


def test_metrics_of_the_committed_bag():
    from avp_bringup.bag import metrics_from_bag

    recomputed, live = metrics_from_bag(EXAMPLE)
    assert recomputed == live and live["steps"] == 40

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
    assert [g.step for g in gts] == list(range(metrics["steps"] + 1))  # every step recorded, in order
    assert len(lots) == 1 and len(lots[0].spots) == 40
    assert topics["/avp/lot_map"].ext.offered_qos_profiles[0].durability.name == "TRANSIENT_LOCAL"
    m = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "metrics", str(bag)], env=ros_env,
                       capture_output=True, text=True, timeout=60)
    assert m.returncode == 0, m.stdout + m.stderr
    assert "equal the live ones" in m.stdout

"""`avp demo` end to end over DDS: metrics.json (with the closed-loop step time), episode.png, episode.gif drawn
from the bag, an MCAP bag that rosbags' reader decodes, and `avp metrics BAG` recomputing the live metrics from the
bag's ground truth; the GIF's frame drawing on a hand-made recording."""

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
    assert metrics["method"] == "bezier" and metrics["ego_node"] == "avp_planner"  # not the scene node, a viewer
    check_step_time(metrics, "lockstep", 40)
    check_gif(out / "episode.gif", min_frames=41)  # t_f = 4 s: every step of 0..40 (stride 1)
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
        traces = [reader.deserialize(raw, c.msgtype) for c, _, raw in
                  reader.messages(connections=[topics["/avp/avp_planner/debug/decision"]])]
    # the decision trace of every step, consistent with the decision, and `avp why` reads it back
    assert [t.step for t in traces] == list(range(metrics["steps"]))
    kinds = {0: {"idle", "parked"}, 1: {"park", "wait_and_go", "detour", "evasive", "creep"},
             2: {"explore", "wait_and_go", "detour", "evasive", "creep"}}
    assert all(t.mode in kinds[d.mode] for t, d in zip(traces, decisions, strict=True))
    assert all((t.cause == "") == (t.idle_steps == 0) for t in traces)
    why = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "why", str(bag)], env=ros_env,
                         capture_output=True, text=True, timeout=60)
    assert why.returncode == 0 and "steps by mode:" in why.stdout, why.stdout + why.stderr
    modes = eval(why.stdout.split("steps by mode: ")[1].splitlines()[0])  # noqa: S307 - our own dict's repr
    assert sum(modes.values()) == metrics["steps"]
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
    check_viewer_topics(bag, metrics["steps"])
    # one file for viewers that open one: every message of every split, unchanged
    merged = tmp_path / "merged.mcap"
    m = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "merge-bag", str(bag), str(merged)], env=ros_env,
                       capture_output=True, text=True, timeout=60)
    assert m.returncode == 0, m.stdout + m.stderr
    from mcap.reader import make_reader

    def messages(files):
        out = []
        for f in files:
            with open(f, "rb") as fh:
                out += [(c.topic, msg.log_time, msg.data) for _s, c, msg in make_reader(fh).iter_messages()]
        return sorted(out)

    assert messages([merged]) == messages(sorted(Path(bag).glob("*.mcap")))


def check_viewer_topics(bag: Path, steps: int) -> None:
    """What Foxglove's 3-D panel needs, read with the independent `mcap` + `mcap-ros2-support` reader
    from every split: the transform tree (REP-105), the scene markers and the scan, stamped with simulated time."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    markers = "visualization_msgs/msg/MarkerArray"
    want = {"/tf": "tf2_msgs/msg/TFMessage", "/tf_static": "tf2_msgs/msg/TFMessage", "/avp/viz/lot": markers,
            "/avp/viz/spots": markers, "/avp/viz/scene": markers, "/avp/debug/scan": "sensor_msgs/msg/LaserScan"}
    got: dict[str, list] = {t: [] for t in want}
    files = sorted(Path(bag).glob("*.mcap"))
    assert files, bag
    for f in files:
        with open(f, "rb") as fh:
            for schema, channel, _msg, dec in make_reader(fh, decoder_factories=[DecoderFactory()]) \
                    .iter_decoded_messages(topics=list(want)):
                assert schema.name == want[channel.topic], (channel.topic, schema.name)
                got[channel.topic].append(dec)
    assert all(len(got[t]) > 0 for t in want), {t: len(v) for t, v in got.items()}
    static = got["/tf_static"][0].transforms[0]
    assert (static.header.frame_id, static.child_frame_id) == ("map", "odom")
    ego_tf = [[t for t in m.transforms if t.child_frame_id == "base_link"] for m in got["/tf"]]
    assert all(len(e) == 1 and e[0].header.frame_id == "odom" for e in ego_tf)
    # one transform and one scene per step, stamped t_k = k * dt (simulated time)
    stamps = [e[0].header.stamp.sec * 10 + e[0].header.stamp.nanosec // 100_000_000 for e in ego_tf]
    assert stamps == list(range(len(stamps))) and len(stamps) >= steps
    scenes = got["/avp/viz/scene"]
    assert len(scenes) >= steps
    layers = set().union(*({m.ns for m in s.markers} for s in scenes))
    assert {"vehicles", "ego", "plan"} <= layers, layers
    assert {m.ns for m in got["/avp/viz/lot"][0].markers} == {"lot"} and len(got["/avp/viz/lot"]) == 1
    # the spot fill: every spot coloured, sent again only when a colour changed
    fills = [next(m for m in a.markers if m.ns == "spots") for a in got["/avp/viz/spots"]]
    assert all(len(f.points) == 6 * 40 and len(f.colors) == len(f.points) for f in fills)
    assert 1 <= len(fills) <= len(scenes)
    assert all(m.header.frame_id == "map" for t in ("/avp/viz/scene", "/avp/viz/lot", "/avp/viz/spots")
               for a in got[t] for m in a.markers if m.ns)
    assert got["/avp/debug/scan"][0].header.frame_id == "base_link" and len(got["/avp/debug/scan"][0].ranges) > 0


def test_demo_parks_on_a_lot_without_a_scenario_block(ros_env, tmp_path):
    """``avp demo --lot`` simulates and plans on the given lot (here the shipped side lot, whose scenario
    roles all come from its geometry) to a parked ego; metrics.json and the bag's lot map name that lot."""
    from avp_world.lot import bundled_lot_path, load_lot

    lot_file = bundled_lot_path("side_lot")
    out, bag = tmp_path / "demo", tmp_path / "bag"
    r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "demo", "--lot", str(lot_file), "--seed", "1",
                        "--no-gif", "--out", str(out), "--bag", str(bag), "--timeout", "300"], env=ros_env,
                       capture_output=True, text=True, timeout=360)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["state"] == "success" and metrics["parked_spot_id"] >= 0, metrics
    assert metrics["lot"] == {"name": "side_lot", "sha256": load_lot(lot_file).sha256}
    from avp_bag.reader import BagReader

    reader = BagReader(bag)
    lots = [reader.deserialize(raw, msgtype) for _, msgtype, _, raw in reader.messages(["/avp/lot_map"])]
    assert len(lots) == 1 and lots[0].name == "side_lot" and len(lots[0].spots) == 27


def test_busy_demo_on_the_dlp_lot_records_pedestrians_and_recomputes(ros_env, tmp_path):
    """The whole graph over DDS on the DLP lot with the busy family: pedestrians and 20+ moving cars in
    the ground truth, the planner answering every step, and `avp metrics` recomputing the live metrics (pedestrian
    collisions included) from the bag."""
    from avp_bag.reader import BagReader
    from avp_world.lot import bundled_lot_path

    out, bag = tmp_path / "demo", tmp_path / "bag"
    r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "demo", "--lot", str(bundled_lot_path("dlp_lot")),
                        "--scenario", "busy", "--seed", "0", "--t-final", "5", "--no-gif", "--out", str(out), "--bag",
                        str(bag), "--timeout", "300"], env=ros_env, capture_output=True, text=True, timeout=360)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["lot"]["name"] == "dlp_lot" and metrics["steps"] == 50 or metrics["state"] != "timeout"
    reader = BagReader(bag)
    gts = [reader.deserialize(raw, mt) for _, mt, _, raw in reader.messages(["/avp/debug/ground_truth"])]
    kinds = [a.kind for a in gts[0].agents]
    assert kinds.count(2) >= 10  # pedestrians
    # moving cars (arrivals stop 10 s before t_f, so a 5 s episode has only the cars already on their way; a 60 s
    # one has 20+: tests/test_lots.py::test_the_busy_family_on_the_dlp_lot)
    assert sum(1 for a in gts[0].agents if a.kind == 1 and not a.is_static) >= 10
    decisions = [reader.deserialize(raw, mt) for _, mt, _, raw in reader.messages(["/avp/decision"])]
    assert [d.step for d in decisions] == list(range(metrics["steps"]))
    m = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "metrics", str(bag)], env=ros_env,
                       capture_output=True, text=True, timeout=120)
    assert m.returncode == 0 and "equal the live ones" in m.stdout, m.stdout + m.stderr


def check_step_time(metrics: dict, mode: str, steps: int) -> None:
    """The closed-loop step time is in metrics.json: one value per answered step, positive, ordered figures."""
    lat = metrics["closed_loop_step_time"]
    assert lat["sim_mode"] == mode and lat["steps"] >= steps - 1 and lat["target_p95_ms"] == 100.0
    assert 0 < lat["min_ms"] <= lat["median_ms"] <= lat["p95_ms"] <= lat["max_ms"]
    assert ("late_steps" in lat) == (mode == "realtime")


def check_gif(path: Path, min_frames: int) -> None:
    """An animated GIF read back by Pillow: enough frames, < 5 MB, and the ego moves (frames differ)."""
    import numpy as np
    from PIL import Image

    assert path.stat().st_size < 5e6
    with Image.open(path) as im:
        assert im.format == "GIF" and im.n_frames >= min_frames and im.size[0] > 300
        im.seek(0)
        first = np.asarray(im.convert("RGB"))
        im.seek(im.n_frames - 1)
        last = np.asarray(im.convert("RGB"))
    assert (first != last).any()


def test_realtime_demo_measures_the_step_time(ros_env, tmp_path):
    """`avp demo --realtime`: the simulator steps on its wall timer; the step time and the late steps are in
    metrics.json (figures in docs/benchmarks.md, bench/bench_live_latency.py — no timed assertion here)."""
    out, bag = tmp_path / "demo", tmp_path / "bag"
    r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "demo", "--seed", "1", "--t-final", "3",
                        "--realtime", "--method", "implicit", "--out", str(out), "--bag", str(bag), "--timeout",
                        "120"], env=ros_env, capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stdout + r.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["lock_step"] is False and metrics["method"] == "implicit" and metrics["steps"] == 30
    check_step_time(metrics, "realtime", 20)  # real time: a command may come too late to be answered at all
    assert "closed-loop step time" in r.stdout and "p95" in r.stdout
    check_gif(out / "episode.gif", min_frames=20)
    from avp_viz.episode_video import read_recording

    rec = read_recording(bag)  # the implicit method's ego intention went over the graph and into the bag
    assert len(rec.ego_intention) >= 20 and all(not its for its in rec.intentions.values())


def test_gif_frame_draws_the_recorded_beliefs_plan_and_ego(paper_lot):
    """render_frame on a hand-made recording: spot fills follow b (0 -> FREE, 1 -> TAKEN, never observed ->
    UNSEEN), the ego rectangle and the plan are where the messages say (pixel positions from the lot's bounds and
    the scale, computed here)."""
    import math
    from types import SimpleNamespace

    import numpy as np

    from avp_viz.episode_video import EGO, FREE, PARK, TAKEN, UNSEEN, EpisodeRecording, render_frame
    from avp_world.types import Observation

    lot = paper_lot
    rec = EpisodeRecording(lot)
    b = np.full(lot.n_spots, 0.5)
    i0, i1, i2 = lot.spot_index(0), lot.spot_index(21), lot.spot_index(39)
    b[i0], b[i1] = 0.0, 1.0
    ego = np.array([21.5, 30.0, -math.pi / 2])
    rec.beliefs[0] = b
    rec.ground_truth[0] = SimpleNamespace(agents=[])
    rec.observations[0] = Observation(step=0, dt=0.1, ego_pose=ego, ego_length=4.6, ego_width=1.85, ego_speed=0.0,
                                      vacant_spot_ids=np.array([0]), occupied_spot_ids=np.array([21]))
    pose = lambda x, y: SimpleNamespace(pose=SimpleNamespace(position=SimpleNamespace(x=x, y=y)))  # noqa: E731
    rec.decisions[0] = SimpleNamespace(mode=1, spot_id=-1, plan=SimpleNamespace(poses=[pose(21.5, 20.0),
                                                                                       pose(10.0, 20.0)]))
    seen = np.zeros(lot.n_spots, dtype=bool)
    seen[[i0, i1]] = True
    s = 12.0
    img = render_frame(rec, 0, seen, px_per_m=s)
    xmin, _, _, ymax = lot.bounds()

    def at(x, y):  # the canvas (margin 1 m) starts below the 22 px header
        return img[22 + int(round((ymax + 1.0 - y) * s)), int(round((x - xmin + 1.0) * s))].tolist()

    def centre(i):
        return lot.spot_poses[i, :2]

    assert at(*centre(i0)) == FREE.tolist() and at(*centre(i1)) == TAKEN.tolist()
    assert at(*centre(i2)) == list(UNSEEN)
    assert at(ego[0], ego[1]) == list(EGO)
    assert at(15.0, 20.0) == list(PARK)


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
                             "--delay", "1", "--wait-subscribers", "--topics", "/avp/observation", "/avp/lot_map"],
                            env=ros_env,
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
    from avp_bag.episode import metrics_from_bag

    recomputed, live = metrics_from_bag(EXAMPLE)
    assert recomputed == live and live["steps"] == 40

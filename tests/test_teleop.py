"""A person at the wheel (docs/teleop.md): driven cars in the simulator, `avp teleop`, Foxglove's clientPublish with an
allow-list. Oracles: eq. (1) integrated here (numpy), shapely footprints, a websocket client speaking the Foxglove
protocol, a pseudo-terminal."""

from __future__ import annotations

import json
import math
import os
import select
import struct
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from shapely.geometry import Polygon

from avp_teleop.teleop import TeleopState, split_keys
from avp_world.geometry import rect_corners
from avp_world.vehicle import VehicleSpec

UP = math.pi / 2
BOTTOM = "21.5,3.5,1.5707963267948966"  # the bottom of the paper lot's middle road, facing up


def _eq1(pose, v: float, omega: float, dt: float = 0.1) -> np.ndarray:
    """Eq. (1), the unicycle step, written out here as the oracle."""
    x, y, th = pose
    return np.array([x + v * math.cos(th) * dt, y + v * math.sin(th) * dt, th + omega * dt])


def _footprint(pose) -> Polygon:
    return Polygon(rect_corners(np.asarray(pose, dtype=float), 4.6, 1.85))


def test_teleop_keys():
    s = TeleopState()
    for k in split_keys("ww\x1b[A\x1b[D" + "a"):
        s.key(k)
    assert (s.v, s.omega) == (1.5, 0.2)
    for k in split_keys("\x1b[B" "d" "x"):
        s.key(k)
    assert (s.v, s.omega) == (1.0, 0.1)
    s.key(" ")
    assert (s.v, s.omega, s.quit) == (0.0, 0.0, False)
    for _ in range(30):
        s.key("s")
    assert s.v == -5.0  # clamped to eq. (1)'s limit
    s.key("q")
    assert s.quit and s.v == 0.0
    assert "/avp/driver0/cmd_vel: v +0.0 m/s" in s.line("/avp/driver0/cmd_vel")


def test_a_driven_car_in_the_world_moves_by_eq1_collides_with_fault_and_never_holds_the_episode(paper_lot):
    from avp_episode.run_config import RunConfig, sim_values
    from avp_sim.core.factory import make_world

    p = sim_values(RunConfig(t_final=30.0))
    p.update({"drivers.count": 1, "drivers.poses": BOTTOM})
    w = make_world(paper_lot, p, 3, True)
    assert (w.egos.count, w.egos.n_auto, list(w.egos.is_driver)) == (2, 1, [False, True])
    w.step_all([(0.0, 0.0), (0.0, 0.0)])  # it enters after the first step
    pose = w.egos.poses[1].copy()
    for u in [(1.0, 0.0)] * 10 + [(1.0, 0.3)] * 10 + [(9.0, 0.0)]:
        w.step_all([(0.0, 0.0), u])
        clipped = w.clip_command(*u)
        pose = _eq1(pose, *clipped)
        assert _footprint(w.egos.poses[1]).symmetric_difference(_footprint(pose)).area < 1e-6
    assert w.clip_command(9.0, 0.0)[0] == 5.0  # speeds above the limit are clamped
    # the ego turns hard into a parked car: its episode is over, and so is the lot's, the driven car still driving
    while not w.done:
        w.step_all([(3.0, 0.9), (1.0, 0.0)])
    assert w.status == "collision" and w.egos.status == ["collision", "running"] and w.step_index < 80
    assert w.egos.ego_name("vehicle:900001") == "driver:0"


def _sim(tmp_path, **extra):
    from avp_bringup.graph import Graph, NodeSpec

    spec = NodeSpec("avp_sim", "avp_sim", "sim_node", "config/sim.param.yaml", {
        "mode": "realtime", "realtime_wait_first_command": False, "drivers.count": 1, "drivers.poses": BOTTOM,
        "seed": 3, "t_final": 120.0, "publish_markers": False, **extra})
    return Graph([spec], tmp_path / "logs")


class _Driven:
    """Ground truth of driven car 0, step by step."""

    def __init__(self, node):
        from rclpy.serialization import deserialize_message

        from avp_common.drain import draining_subscription
        from avp_common.qos import GROUND_TRUTH
        from avp_msgs.msg import AgentState, GroundTruth

        self.poses: dict[int, np.ndarray] = {}
        self.ego: np.ndarray | None = None  # the ego's latest pose
        self.sent_ns: dict[int, int] = {}  # step -> when the simulator sent its ground truth (DDS source timestamp)

        def cb(raw, info) -> None:
            m = deserialize_message(raw, GroundTruth)
            for a in m.agents:
                if a.kind == AgentState.KIND_EGO:
                    self.ego = np.array([a.pose.x, a.pose.y, a.pose.theta])
                if a.kind == AgentState.KIND_DRIVEN and a.id == 0:
                    self.poses[int(m.step)] = np.array([a.pose.x, a.pose.y, a.pose.theta])
                    self.sent_ns[int(m.step)] = int(info["source_timestamp"])

        draining_subscription(node, GroundTruth, "/avp/debug/ground_truth", cb, GROUND_TRUTH, with_info=True)

    def moves(self) -> list[tuple[int, float, float]]:
        """(step, speed, yaw rate) of each step's motion, read back through eq. (1)."""
        ks = sorted(self.poses)
        out = []
        for a, b in zip(ks, ks[1:], strict=False):
            if b != a + 1:
                continue
            d = self.poses[b] - self.poses[a]
            th = self.poses[a][2]
            out.append((b, float(d[0] * math.cos(th) + d[1] * math.sin(th)) / 0.1, float(d[2]) / 0.1))
        return out


def _spin_for(node, seconds: float, each=None) -> None:
    import rclpy

    t0 = time.monotonic()
    while time.monotonic() - t0 < seconds:
        rclpy.spin_once(node, timeout_sec=0.02)
        if each is not None:
            each()


@pytest.mark.parametrize("stamped", [False, True])
def test_twist_commands_drive_the_car_and_a_stale_one_stops_it(ros_env, tmp_path, monkeypatch, stamped):
    import rclpy
    from geometry_msgs.msg import Twist, TwistStamped

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    rclpy.init()
    node = rclpy.create_node("driver_probe", namespace="/avp")
    pub = node.create_publisher(TwistStamped if stamped else Twist, "driver0/cmd_vel", 10)
    driven = _Driven(node)
    graph = _sim(tmp_path, **{"drivers.stamped": stamped})
    graph.start()
    cmd = {"v": 0.0, "w": 0.0}
    last = {"t": 0.0}

    def send() -> None:
        if time.monotonic() - last["t"] >= 0.05:  # 20 Hz
            t = Twist()
            t.linear.x, t.angular.z = cmd["v"], cmd["w"]
            pub.publish(TwistStamped(twist=t) if stamped else t)
            last["t"], last["ns"] = time.monotonic(), time.time_ns()

    try:
        t0 = time.monotonic()
        while len(driven.poses) < 5 and time.monotonic() - t0 < 60:
            _spin_for(node, 0.2)
        assert driven.poses, "the driven car never entered"
        start = driven.poses[min(driven.poses)]
        assert _footprint(start).symmetric_difference(_footprint([21.5, 3.5, UP])).area < 1e-6
        cmd.update(v=1.0, w=0.0)
        _spin_for(node, 1.5, send)
        cmd.update(v=1.0, w=0.3)
        _spin_for(node, 1.5, send)
        cmd.update(v=50.0, w=0.0)  # far above the limit
        _spin_for(node, 0.5, send)
        _spin_for(node, 3.0)  # nothing sent: the watchdog (0.5 s) stops the car
    finally:
        graph.stop()
        node.destroy_node()
        rclpy.try_shutdown()
    moves = driven.moves()
    seen = {(round(v, 6), round(w, 6)) for _, v, w in moves}
    # every step's motion is eq. (1) with one of the commands sent, clamped (or a stop)
    assert seen <= {(0.0, 0.0), (1.0, 0.0), (1.0, 0.3), (5.0, 0.0)}, seen
    assert {(1.0, 0.0), (1.0, 0.3), (5.0, 0.0)} <= seen, seen
    assert all(abs(v) <= 5.0 + 1e-9 for _, v, _ in moves)
    # stopped within the watchdog plus a step, by the simulator's own clock (the DDS source timestamps of the ground
    # truth, not when it reached this process: on a loaded machine that comes late), with 0.5 s for the last
    # command's trip and the step's work; and it stays stopped
    last_moving = max(k for k, v, _ in moves if v != 0.0)
    assert (driven.sent_ns[last_moving] - last["ns"]) * 1e-9 <= 0.5 + 0.1 + 0.5, (last_moving, moves[-20:])
    assert len([k for k, _, _ in moves if k > last_moving]) >= 10 and moves[-1][1] == 0.0
    # footprints (shapely) of the recorded poses against eq. (1) integrated from the first one
    ks = sorted(driven.poses)
    pose = driven.poses[ks[0]]
    for (k, v, w) in moves:
        pose = _eq1(driven.poses[k - 1], v, w)
        assert _footprint(driven.poses[k]).symmetric_difference(_footprint(pose)).area < 1e-6


def test_foxglove_clients_may_drive_only_the_driven_cars(ros_env, tmp_path, monkeypatch):
    import threading

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from websockets.sync.client import connect

    from avp_viz.foxglove_bridge import FoxgloveBridge

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    rclpy.init()
    bridge = FoxgloveBridge(port=0, drive=True)
    probe = rclpy.create_node("fox_probe", namespace="/avp")
    driven = _Driven(probe)
    ex = SingleThreadedExecutor()
    ex.add_node(bridge)
    ex.add_node(probe)
    stop = threading.Event()
    spinner = threading.Thread(target=lambda: [ex.spin_once(timeout_sec=0.05) for _ in iter(stop.is_set, True)])
    spinner.start()
    graph = _sim(tmp_path)
    graph.start()
    status: list[dict] = []
    try:
        with connect(f"ws://127.0.0.1:{bridge.port}", subprotocols=["foxglove.sdk.v1"]) as ws:
            info = json.loads(ws.recv(timeout=10))
            assert info["op"] == "serverInfo" and "clientPublish" in info["capabilities"], info
            ws.send(json.dumps({"op": "advertise", "channels": [
                {"id": 1, "topic": "/avp/driver0/cmd_vel", "encoding": "json", "schemaName": "geometry_msgs/msg/Twist"},
                {"id": 2, "topic": "/avp/cmd", "encoding": "json", "schemaName": "geometry_msgs/msg/TwistStamped"},
                {"id": 3, "topic": "/avp/driver0/cmd_vel", "encoding": "json", "schemaName": "std_msgs/msg/String"},
            ]}))
            t0 = time.monotonic()
            while len(driven.poses) < 5 and time.monotonic() - t0 < 60:
                time.sleep(0.1)
            twist = json.dumps({"linear": {"x": 2.0, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": 0}}).encode()
            t1 = time.monotonic()
            while time.monotonic() - t1 < 2.0:
                for ch in (1, 2, 3):
                    ws.send(b"\x01" + struct.pack("<I", ch) + twist)
                time.sleep(0.1)
                try:
                    while True:
                        m = ws.recv(timeout=0.01)
                        if isinstance(m, str) and json.loads(m).get("op") == "status":
                            status.append(json.loads(m))
                except TimeoutError:
                    pass
    finally:
        graph.stop()
        stop.set()
        spinner.join()
        bridge.close()
        bridge.destroy_node()
        probe.destroy_node()
        rclpy.try_shutdown()
    assert bridge.drive.forwarded > 5
    assert {r.split(": ", 1)[1] for r in bridge.drive.refused} == {"/avp/cmd", "/avp/driver0/cmd_vel"}
    assert any("refused" in s["message"] and "/avp/cmd" in s["message"] for s in status), status
    moved = [v for _, v, _ in driven.moves() if v != 0.0]
    assert moved and set(np.round(moved, 6)) == {2.0}  # the Teleop-style client drove it at 2 m/s


def test_avp_teleop_in_a_pseudo_terminal_sends_what_the_keys_say(ros_env, monkeypatch):
    import pty

    import rclpy
    from geometry_msgs.msg import Twist

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    rclpy.init()
    node = rclpy.create_node("teleop_probe")
    got: list[tuple[float, float]] = []
    node.create_subscription(Twist, "/avp/driver1/cmd_vel", lambda m: got.append((m.linear.x, m.angular.z)), 10)
    pid, fd = pty.fork()
    if pid == 0:  # the child: avp teleop on the pseudo-terminal
        os.execve(sys.executable, [sys.executable, "-m", "avp_bringup.cli", "teleop", "--driver", "1"],
                  dict(os.environ))
    screen = bytearray()

    def spin(timeout: float) -> None:  # and read the terminal: a full pty would block the child
        rclpy.spin_once(node, timeout_sec=timeout)
        while select.select([fd], [], [], 0)[0]:
            try:
                chunk = os.read(fd, 4096)
            except OSError:
                return
            if not chunk:
                return
            screen.extend(chunk)

    try:
        t0 = time.monotonic()
        while not got and time.monotonic() - t0 < 60:
            spin(0.1)
        assert got and got[-1] == (0.0, 0.0)
        for keys, want in ((b"ww\x1b[A", (1.5, 0.0)), (b"a\x1b[D", (1.5, 0.2)), (b"s", (1.0, 0.2)), (b" ", (0.0, 0.0)),
                           (b"\x1b[B", (-0.5, 0.0))):
            os.write(fd, keys)
            t1 = time.monotonic()
            while (not got or got[-1] != want) and time.monotonic() - t1 < 10:
                spin(0.05)
            assert got[-1] == want, (keys, got[-5:])
        n = len(got)
        t1 = time.monotonic()
        while time.monotonic() - t1 < 1.0:
            spin(0.05)
        assert 4 <= len(got) - n <= 16  # ~10 Hz whether or not a key is pressed
        os.write(fd, b"q")
        t1 = time.monotonic()
        done = 0
        while time.monotonic() - t1 < 20 and not done:
            spin(0.05)
            done, status = os.waitpid(pid, os.WNOHANG)
        assert done, "avp teleop did not quit on q"
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    assert os.waitstatus_to_exitcode(status) == 0
    assert got[-1] == (0.0, 0.0)  # q sends a stop
    assert b"/avp/driver1/cmd_vel: v" in bytes(screen)


def test_the_pipeline_never_reads_a_drivers_commands():
    """No ego-side module subscribes to a driver's topic: the driven car is an observed vehicle like any other."""
    src = Path(__file__).resolve().parents[1] / "src"
    ego_side = [*src.glob("avp_planner/avp_planner/**/*.py"), *src.glob("avp_perception/avp_perception/**/*.py"),
                src / "avp_episode/avp_episode/ego.py"]
    assert ego_side
    for f in ego_side:
        text = f.read_text()
        assert "cmd_vel" not in text and "driver0" not in text and "KIND_DRIVEN" not in text, f
    sim = (src / "avp_sim/avp_sim/core/world.py").read_text()
    assert "observe" in sim and "cmd_vel" not in sim  # the world knows poses, never a person's commands


def test_demo_drive_records_the_driven_car_and_metrics_recompute_it(ros_env, tmp_path, monkeypatch):
    """`avp demo --drive` (real time): a scripted person drives car 0 in after the ego; the ego parks
    (or times out) without a collision, the bag has the driven car's commands and ground truth, and `avp metrics`
    recomputes the live metrics from it."""
    import subprocess

    import rclpy
    from geometry_msgs.msg import Twist

    from avp_bag.episode import metrics_from_bag

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    out, bag = tmp_path / "demo", tmp_path / "bag"
    # t_f 180 s of real time: the episode ends when the ego parks (about 25 s in on an idle machine); a step answered
    # late holds the ego, and with four test processes on 2 cores (CI) 60 s ran out before the ego was 10 m ahead
    demo = subprocess.Popen([sys.executable, "-m", "avp_bringup.cli", "demo", "--drive", "--seed", "1", "--t-final",
                             "180", "--no-gif", "--out", str(out), "--bag", str(bag)], env=ros_env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    rclpy.init()
    node = rclpy.create_node("person", namespace="/avp")
    pub = node.create_publisher(Twist, "driver0/cmd_vel", 10)
    driven = _Driven(node)
    try:
        t0 = time.monotonic()
        while not driven.poses and demo.poll() is None and time.monotonic() - t0 < 300:
            rclpy.spin_once(node, timeout_sec=0.1)
        assert driven.poses, "the driven car never entered"
        timeline = [f"entered at step {min(driven.poses)} ({time.monotonic() - t0:.1f} s)"]

        body = VehicleSpec()

        def here() -> np.ndarray:
            """The driven car's latest pose."""
            return driven.poses[max(driven.poses)]

        def gap() -> float:
            """Centre-to-centre distance from the driven car to the ego."""
            return float(np.hypot(*(driven.ego[:2] - here()[:2]))) if driven.ego is not None else 0.0

        def clearance() -> float:
            """Free space between the two bodies (shapely), as a person judges it through the windscreen."""
            if driven.ego is None:
                return 0.0
            car = Polygon(rect_corners(here(), body.length, body.width))
            return float(car.distance(Polygon(rect_corners(driven.ego, body.length, body.width))))

        # a person waits until the car ahead has pulled away, at most 60 s: on CI's loaded machine the ego, held on
        # every step its planner answers late, once stayed 7.3 m ahead of the gate until t_f (the person then waited
        # for a 10 m gap that never came, and never drove)
        t1 = time.monotonic()
        while gap() < 10.0 and demo.poll() is None and time.monotonic() - t1 < 60:
            rclpy.spin_once(node, timeout_sec=0.1)
        timeline.append(f"drives at step {max(driven.poses)} ({time.monotonic() - t0:.1f} s), the ego {gap():.1f} m "
                        f"ahead, the demo {'ended' if demo.poll() is not None else 'running'}")
        t1 = time.monotonic()
        start = here()[:2]

        def moved() -> float:
            return float(np.hypot(*(here()[:2] - start)))

        # 0.8 m/s down the road from the gate until the car has moved 1.5 m (2 s on an idle machine; a loaded one
        # drops commands older than drivers.watchdog) while more than 1.5 m stays free ahead, then let go
        while demo.poll() is None and time.monotonic() - t1 < 60.0 and moved() < 1.5:
            free = clearance() > 1.5
            if not free and moved() > 0.3:
                break  # it has driven; the ego is too close to go on
            t = Twist()
            t.linear.x = 0.8 if free else 0.0
            pub.publish(t)
            _spin_for(node, 0.1)
        timeline.append(f"let go at step {max(driven.poses)} ({time.monotonic() - t0:.1f} s), moved "
                        f"{moved():.2f} m, {clearance():.1f} m free")
        text = demo.communicate(timeout=600)[0]
        print("[drive]", "; ".join(timeline))  # pytest -s
    finally:
        if demo.poll() is None:
            demo.kill()
        node.destroy_node()
        rclpy.try_shutdown()
    assert demo.returncode == 0, text[-3000:]
    assert any(v > 0 for _, v, _ in driven.moves()), (timeline, text[-3000:])
    recomputed, live = metrics_from_bag(bag)
    assert recomputed == live, (recomputed, live)
    # the ego parks (seed 1, about 25 s in) with the driven car behind it. In real time the timing, and so the
    # ego's choices, differ from run to run: once on CI's loaded machine it had not parked at t_f (cause not
    # recorded; the failure now prints the sim's log). Either way, no collision
    sim_log = (out / "logs" / "avp_sim.log").read_text()[-3000:]
    assert live["state"] in ("success", "timeout") and not live["collision"], (live, timeline, sim_log)
    if live["state"] != "success":
        print("[drive] the ego did not park:", live, sim_log)
    from rosbags.rosbag2 import Reader

    with Reader(bag) as reader:
        topics = {c.topic: c.msgcount for c in reader.connections}
    assert topics.get("/avp/driver0/cmd_vel", 0) >= 10, topics
    from avp_bag.episode import ego_metrics_from_bag

    car = ego_metrics_from_bag(bag, 0, driver=True)  # `avp metrics BAG --driver 0`: the driven car's own record
    assert car["driver"] == 0 and car["entered_step"] is not None and car["steps_in_the_lot"] > 0, car
    assert car["interrupted_steps"] >= 0 and car["collision"] == (car["collision_with"] != "")


def test_a_driver_of_the_other_message_type_is_named(ros_env, tmp_path, monkeypatch):
    """A person's tool sending ``Twist`` where the simulator reads ``TwistStamped`` (``drivers.stamped: true``)
    matches no reader and DDS tells neither side: the simulator names that publisher, its node and type, in one
    warning (avp_sim.ego_channels.DriverTypeCheck), and the car does not move."""
    import rclpy
    from geometry_msgs.msg import Twist, Vector3

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    rclpy.init()
    node = rclpy.create_node("wrong_type_driver", namespace="/avp")
    pub = node.create_publisher(Twist, "driver0/cmd_vel", 10)
    driven = _Driven(node)
    graph = _sim(tmp_path, **{"drivers.stamped": True})
    graph.start()
    log = tmp_path / "logs" / "avp_sim.log"
    wanted = "/avp/driver0/cmd_vel: /avp/wrong_type_driver publishes geometry_msgs/msg/Twist, but the simulator reads "
    try:
        t0 = time.monotonic()
        while time.monotonic() - t0 < 60 and not (len(driven.poses) >= 10 and log.exists()
                                                  and wanted in log.read_text()):
            pub.publish(Twist(linear=Vector3(x=1.0)))
            _spin_for(node, 0.1)
    finally:
        graph.stop()
        node.destroy_node()
        rclpy.try_shutdown()
    text = log.read_text()
    assert wanted + "geometry_msgs/msg/TwistStamped (drivers.stamped: true): its commands never arrive" in text, text
    assert text.count(wanted) == 1  # once, though it kept publishing
    assert driven.poses and all(v == 0.0 for _, v, _ in driven.moves())

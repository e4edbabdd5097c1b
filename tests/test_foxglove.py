"""`avp demo --foxglove` serves the running graph over the Foxglove WebSocket protocol (docs/foxglove.md): a real
WebSocket client (the `websockets` library, the protocol's `foxglove.sdk.v1` subprotocol) connects to the demo's
server, subscribes to /tf and receives the graph's transforms as CDR that the ROS 2 type decodes."""

from __future__ import annotations

import json
import socket
import struct
import subprocess
import sys
import time

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("foxglove")
ws_client = pytest.importorskip("websockets.sync.client")

MESSAGE_DATA = 0x01  # binary opcode of a message from the server (Foxglove WebSocket protocol)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_for_line(proc: subprocess.Popen, needle: str, timeout: float) -> str:
    deadline = time.monotonic() + timeout
    seen = []
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line and proc.poll() is not None:
            break
        seen.append(line)
        if needle in line:
            return line
    raise AssertionError(f"no {needle!r} from the demo:\n" + "".join(seen[-40:]))


def test_a_websocket_client_subscribes_and_receives_the_graphs_transforms(ros_env, tmp_path):
    from rclpy.serialization import deserialize_message
    from tf2_msgs.msg import TFMessage

    port = _free_port()
    proc = subprocess.Popen([sys.executable, "-m", "avp_bringup.cli", "demo", "--seed", "1", "--t-final", "30",
                             "--no-gif", "--realtime", "--foxglove", "--foxglove-port", str(port), "--out",
                             str(tmp_path / "demo"), "--bag", str(tmp_path / "bag"), "--timeout", "120"],
                            env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        _wait_for_line(proc, f"ws://127.0.0.1:{port}", 60)
        with ws_client.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], compression=None,
                               open_timeout=60) as ws:
            info = json.loads(ws.recv(timeout=30))
            assert info["op"] == "serverInfo"
            channels: dict[str, dict] = {}
            deadline = time.monotonic() + 30
            while "/tf" not in channels and time.monotonic() < deadline:
                msg = ws.recv(timeout=30)
                if isinstance(msg, str) and json.loads(msg)["op"] == "advertise":
                    channels.update({c["topic"]: c for c in json.loads(msg)["channels"]})
            assert {"/tf", "/tf_static", "/avp/viz/scene", "/avp/debug/scan"} <= set(channels), sorted(channels)
            tf = channels["/tf"]
            assert (tf["encoding"], tf["schemaName"], tf["schemaEncoding"]) == ("cdr", "tf2_msgs/msg/TFMessage",
                                                                                "ros2msg")
            assert "geometry_msgs/TransformStamped[] transforms" in tf["schema"]
            ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 7, "channelId": tf["id"]}]}))
            received = []
            deadline = time.monotonic() + 60
            while len(received) < 5 and time.monotonic() < deadline:
                msg = ws.recv(timeout=30)
                if isinstance(msg, bytes) and msg[0] == MESSAGE_DATA:
                    sub_id, log_time = struct.unpack_from("<IQ", msg, 1)
                    assert sub_id == 7
                    received.append((log_time, deserialize_message(msg[13:], TFMessage)))
    finally:
        proc.terminate()
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
    assert len(received) == 5
    for log_time, m in received:
        ego = [t for t in m.transforms if t.child_frame_id == "base_link"]
        assert len(ego) == 1 and ego[0].header.frame_id == "odom"
        stamp = ego[0].header.stamp.sec * 1_000_000_000 + ego[0].header.stamp.nanosec
        # simulated time (step k * dt), not the wall clock (about 1.8e18 ns since 1970): the log time is the bridge's
        # simulated time when it forwarded the message, some steps later on a loaded machine (0.7 s seen at load 10)
        assert stamp % 100_000_000 == 0 and abs(log_time - stamp) <= 5_000_000_000

"""avp_common.received (one message per payload in a container; a stamp read from the bytes) and the bag writer's
YAML (libyaml's emitter must write what PyYAML's own does)."""

from __future__ import annotations

import pytest

pytest.importorskip("rclpy")

from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import Pose2D, TwistStamped  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402

from avp_common import received  # noqa: E402
from avp_msgs.msg import Observation, ObservedVehicle  # noqa: E402


def _obs(sec: int, nanosec: int, n: int = 3) -> bytes:
    msg = Observation()
    msg.header.stamp = Time(sec=sec, nanosec=nanosec)
    msg.header.frame_id = "map#0123456789abcdef" + "0" * 32
    msg.vehicles = [ObservedVehicle(id=i, history=[Pose2D(x=float(i), y=1.0, theta=0.5)] * 10) for i in range(n)]
    return serialize_message(msg)


@pytest.mark.parametrize(("sec", "nanosec"), [(0, 0), (12, 500_000_000), (2**31 - 1, 999_999_999), (-3, 7)])
def test_the_stamp_read_from_the_bytes_is_the_deserialised_one(sec, nanosec):
    from rclpy.serialization import deserialize_message

    for raw in (_obs(sec, nanosec), _obs(sec, nanosec, 0)):
        msg = deserialize_message(raw, Observation)
        assert received.stamp_ns(raw) == msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
    tw = TwistStamped()
    tw.header.stamp = Time(sec=sec, nanosec=nanosec)
    assert received.stamp_ns(serialize_message(tw)) == sec * 1_000_000_000 + nanosec
    with pytest.raises(ValueError, match="holds no header stamp"):
        received.stamp_ns(b"\x00\x01\x00\x00")


def test_a_container_shares_one_message_per_payload_and_a_lone_node_gets_its_own():
    a, b = _obs(1, 2), _obs(1, 3)
    try:
        received.share_received(False)
        assert received.deserialize(a, Observation) is not received.deserialize(a, Observation)
        received.share_received(True)
        first = received.deserialize(a, Observation)
        assert received.deserialize(bytes(bytearray(a)), Observation) is first  # equal bytes, another object
        assert received.deserialize(b, Observation) is not first
        assert received.deserialize(b, Observation).header.stamp.nanosec == 3
        assert first == received.deserialize(a, Observation) and first.vehicles[2].history[9].x == 2.0
        for k in range(received._SHARED_SIZE + 1):  # bounded: the oldest payload is forgotten
            received.deserialize(_obs(100 + k, 0), Observation)
        assert len(received._shared) == received._SHARED_SIZE
        assert received.deserialize(a, Observation) is not first
    finally:
        received.share_received(False)


def test_the_bag_writers_yaml_is_pyyamls():
    import yaml

    from avp_bag.writer import _yaml

    data = {"rosbag2_bagfile_information": {"version": 9, "files": [
        {"path": f"bag_{i}.mcap", "starting_time": {"nanoseconds_since_epoch": 10**18 + i},
         "duration": {"nanoseconds": 999}, "message_count": i} for i in range(40)],
        "topics_with_message_count": [{"topic_metadata": {"name": "/avp/ego0/observation", "type": "a/b/C",
                                                          "offered_qos_profiles": "- history: 1\n  depth: 5\n",
                                                          "type_description_hash": "RIHS01_" + "ab" * 32},
                                       "message_count": 7}],
        "custom_data": None, "ros_distro": "rosbags", "compression_format": ""}}
    for sort_keys in (True, False):
        assert _yaml(data, sort_keys) == yaml.safe_dump(data, default_flow_style=False, sort_keys=sort_keys)


@pytest.mark.parametrize("frame_len", range(0, 20))
def test_the_observation_head_read_from_the_bytes_is_the_deserialised_one(frame_len):
    """Every frame length moves the 8-byte fields after it to another alignment: each must read what
    rclpy's own deserialiser (the oracle) builds, on little- and big-endian CDR alike."""
    from rclpy.serialization import deserialize_message

    msg = Observation(step=2**40 + 3 * frame_len, dt=0.1 * (frame_len + 1))
    msg.header.stamp = Time(sec=frame_len, nanosec=123_456_789)
    msg.header.frame_id = "m" * frame_len
    msg.ego_pose = Pose2D(x=-1.5 * frame_len, y=2.25, theta=-3.0)
    msg.vehicles = [ObservedVehicle(id=i, history=[Pose2D(x=float(i), y=1.0, theta=0.5)] * 4) for i in range(3)]
    raw = serialize_message(msg)
    want = deserialize_message(raw, Observation)
    head = received.observation_head(raw)
    assert head.header == want.header and head.ego_pose == want.ego_pose
    assert (head.step, head.dt) == (want.step, want.dt)
    big = _big_endian_head(raw, frame_len)
    assert received.observation_head(big) == head


def _big_endian_head(raw: bytes, frame_len: int) -> bytes:
    """The head of ``raw`` (little-endian CDR) written big-endian: every number of it byte-swapped in place."""
    import struct

    body = bytearray(raw[4:])
    for fmt, pos in (("i", 0), ("I", 4), ("I", 8)):
        body[pos:pos + 4] = struct.pack(">" + fmt, struct.unpack_from("<" + fmt, body, pos)[0])
    pos = (12 + frame_len + 1 + 7) // 8 * 8
    for j, fmt in enumerate("Qdddd"):
        at = pos + 8 * j
        body[at:at + 8] = struct.pack(">" + fmt, struct.unpack_from("<" + fmt, body, at)[0])
    return b"\x00\x00\x00\x00" + bytes(body)


@pytest.mark.parametrize("data", [b"", b"\x00\x01\x00\x00", b"\x00\x05\x00\x00" + b"\x00" * 60,
                                  b"\x00\x01\x00\x00" + b"\x00" * 8 + b"\xff\xff\x00\x00" + b"\x00" * 40])
def test_bytes_that_hold_no_observation_head_are_refused(data):
    with pytest.raises(ValueError):
        received.observation_head(data)


def test_a_frozen_start_up_heap_still_collects_what_comes_after():
    """node_main.freeze_start_up_heap: what exists at start-up leaves the collector's generations; a cycle made
    afterwards is still collected."""
    import gc
    import weakref

    from avp_common.node_main import freeze_start_up_heap

    class Cycle:
        pass

    try:
        before = Cycle()
        before.me = before
        freeze_start_up_heap()
        assert gc.get_freeze_count() > 0
        assert all(before is not o for o in gc.get_objects(2))  # frozen: no collection traverses it
        after = Cycle()
        after.me = after
        gone = weakref.ref(after)
        del after
        gc.collect()
        assert gone() is None
    finally:
        gc.unfreeze()

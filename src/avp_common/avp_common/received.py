"""Received messages: one deserialisation per process, and a stamp read without any.

rclpy has no intra-process transport: nodes of one component container (avp_common.container) each get the same
bytes over DDS and would each build the same Python message from them — for an observation of the busy lot, several
hundred ``Pose2D`` objects per subscriber and step. :func:`share_received` makes :func:`deserialize` hand every
subscription of the process one message per distinct payload, as rclcpp's intra-process delivery hands several
subscribers one ``const`` message: the nodes then must not modify what they receive, which avp's nodes never do (they
convert it, :mod:`avp_common.conversions`). It is off unless a container turns it on, so a node in a process of its
own gets a message of its own, as before.

:func:`stamp_ns` reads ``header.stamp`` straight from the serialised bytes (a reader that needs only the step time,
avp_monitor.monitor); :func:`observation_head` reads an observation's fields before its first sequence (a reader that
needs only the step and the ego's pose, avp_planner.v2v_node).
"""

from __future__ import annotations

import struct
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose2D
from rclpy.serialization import deserialize_message
from std_msgs.msg import Header

_shared: OrderedDict | None = None  # (type, payload) -> message, the newest last; None: every call deserialises
_SHARED_SIZE = 16  # payloads remembered: a step's inputs of one ego pipeline, with room


def share_received(on: bool = True) -> None:
    """Let every subscription of this process share one message per distinct payload (see the module's text)."""
    global _shared
    _shared = OrderedDict() if on else None


def deserialize(data: bytes, msg_type: type) -> Any:
    """``deserialize_message(data, msg_type)``; with :func:`share_received`, the message built from the same bytes
    earlier in this process when there was one."""
    if _shared is None:
        return deserialize_message(data, msg_type)
    key = (msg_type, bytes(data))
    msg = _shared.get(key)
    if msg is None:
        msg = _shared[key] = deserialize_message(data, msg_type)
        if len(_shared) > _SHARED_SIZE:
            _shared.popitem(last=False)
    else:
        _shared.move_to_end(key)
    return msg


def stamp_ns(data: bytes) -> int:
    """``header.stamp`` in ns of a serialised message whose first field is its ``std_msgs/Header`` (CDR: a 4-byte
    encapsulation header, then int32 sec and uint32 nanosec in the byte order it names). ValueError for a payload
    too short to hold one."""
    if len(data) < 12:
        raise ValueError(f"a {len(data)}-byte payload holds no header stamp")
    order = "little" if data[1] & 1 else "big"  # CDR_LE / CDR_BE encapsulation
    sec = int.from_bytes(data[4:8], order, signed=True)
    return sec * 1_000_000_000 + int.from_bytes(data[8:12], order)


#: CDR encapsulation kinds (the 2nd byte of a payload): byte order and the largest alignment of a primitive
_ENCAPSULATIONS = {0x00: (">", 8), 0x01: ("<", 8), 0x06: (">", 4), 0x07: ("<", 4)}  # CDR / PLAIN_CDR2, BE / LE


@dataclass(frozen=True)
class ObservationHead:
    """The fields of an ``avp_msgs/Observation`` that come before its arrays, under the same names."""

    header: Header
    step: int
    dt: float
    ego_pose: Pose2D


def observation_head(data: bytes) -> ObservationHead:
    """:class:`ObservationHead` of a serialised ``avp_msgs/Observation``: ``header``, ``step``, ``dt``, ``ego_pose``
    read from the bytes, the rest (on the busy lot hundreds of poses) left unread. CDR (XCDR1 or 2): a 4-byte
    encapsulation header, then each field aligned to its size (at most :data:`_ENCAPSULATIONS`' bound) counted from
    the end of that header; a string is a uint32 length that counts its NUL. ValueError for bytes that hold no such
    head."""
    if len(data) < 4 or data[0] != 0 or data[1] not in _ENCAPSULATIONS:
        raise ValueError(f"not a CDR payload (encapsulation {bytes(data[:2]).hex() or 'missing'})")
    order, max_align = _ENCAPSULATIONS[data[1]]
    body = memoryview(data)[4:]
    try:
        sec, nanosec, n = struct.unpack_from(order + "iII", body, 0)
        if n > len(body) - 12:
            raise ValueError(f"frame_id of {n} bytes in a {len(body)}-byte body")
        frame = bytes(body[12:12 + max(n - 1, 0)]).decode()
        pos = (12 + n + max_align - 1) // max_align * max_align
        step, dt, x, y, theta = struct.unpack_from(order + "Qdddd", body, pos)
    except (struct.error, UnicodeDecodeError) as exc:
        raise ValueError(f"a {len(data)}-byte payload holds no observation head: {exc}") from None
    return ObservationHead(Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame), int(step), float(dt),
                           Pose2D(x=x, y=y, theta=theta))

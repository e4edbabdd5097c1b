"""Received messages: one deserialisation per process, and a stamp read without any.

rclpy has no intra-process transport: nodes of one component container (avp_bringup.container) each get the same
bytes over DDS and would each build the same Python message from them — for an observation of the busy lot, several
hundred ``Pose2D`` objects per subscriber and step. :func:`share_received` makes :func:`deserialize` hand every
subscription of the process one message per distinct payload, as rclcpp's intra-process delivery hands several
subscribers one ``const`` message: the nodes then must not modify what they receive, which avp's nodes never do (they
convert it, :mod:`avp_common.conversions`). It is off unless a container turns it on, so a node in a process of its
own gets a message of its own, as before.

:func:`stamp_ns` reads ``header.stamp`` straight from the serialised bytes (a reader that needs only the step time,
avp_bringup.monitor).
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any

from rclpy.serialization import deserialize_message

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

"""Drive a car from Foxglove's Teleop panel (docs/teleop.md): the live server's ``clientPublish``, with an allow-list.

The bridge (:mod:`avp_viz.foxglove_bridge`) advertises the ``clientPublish`` capability with the encodings ``json``
and ``cdr``. A client may publish only ``geometry_msgs/msg/Twist`` on a driven car's topic,
``/avp/driver<j>/cmd_vel`` (:data:`ALLOWED`); what it sends there is republished on ROS as a Twist, which the
simulator applies to car j at its next step. A client that advertises any other topic — the ego's ``/avp/cmd``, a
pipeline input, a parameter — is refused: one log line naming the client and the topic, a status message to that
client, and its messages on that channel are dropped unread. foxglove_bridge's ``client_topic_whitelist`` is ``.*``
by default; ours is closed by default.
"""

from __future__ import annotations

import json
import re
import threading

from foxglove.websocket import ServerListener

#: the topics a Foxglove client may publish to
ALLOWED = re.compile(r"^/avp/driver[0-9]+/cmd_vel$")
TWIST = "geometry_msgs/msg/Twist"
MAX_MESSAGE_BYTES = 4096  # a Twist is 52 bytes in CDR, about 100 in JSON


class DriveListener(ServerListener):
    """A foxglove-sdk ``ServerListener``: client channels on :data:`ALLOWED` topics are republished on ROS."""

    def __init__(self, node) -> None:
        from geometry_msgs.msg import Twist

        self.node = node
        self.twist = Twist
        self.server = None  # set by the bridge once the server runs (for status messages)
        self.channels: dict[tuple[int, int], tuple[str, str]] = {}  # (client, channel) -> (topic, encoding)
        self.publishers: dict[str, object] = {}
        self.refused: list[str] = []  # "client <id>: <topic>" for each refused advertisement
        self.forwarded = 0
        self.lock = threading.Lock()

    def on_client_advertise(self, client, channel) -> None:
        topic, enc, schema = str(channel.topic), str(channel.encoding), str(channel.schema_name or "")
        ok = bool(ALLOWED.match(topic)) and schema in (TWIST, "") and enc in ("json", "cdr")
        with self.lock:
            if not ok:
                why = (f"client {client.id} advertised {topic!r} ({schema or 'no schema'}, {enc}): refused; a Foxglove "
                       f"client may publish only {TWIST} on /avp/driver<j>/cmd_vel (docs/teleop.md)")
                self.refused.append(f"client {client.id}: {topic}")
                self.node.get_logger().warning(why)
                if self.server is not None:
                    from foxglove.websocket import StatusLevel

                    self.server.publish_status(why, StatusLevel.Error)
                return
            self.channels[(client.id, channel.id)] = (topic, enc)
            if topic not in self.publishers:
                self.publishers[topic] = self.node.create_publisher(self.twist, topic, 10)
        self.node.get_logger().info(f"client {client.id} drives on {topic} ({enc})")

    def on_client_unadvertise(self, client, client_channel_id: int) -> None:
        with self.lock:
            self.channels.pop((client.id, client_channel_id), None)

    def on_message_data(self, client, client_channel_id: int, data: bytes) -> None:
        with self.lock:
            entry = self.channels.get((client.id, client_channel_id))
            pub = self.publishers.get(entry[0]) if entry else None
        if entry is None or pub is None or len(data) > MAX_MESSAGE_BYTES:
            return  # a refused or unknown channel, or an oversized message: dropped unread
        try:
            msg = self._decode(bytes(data), entry[1])
        except (ValueError, TypeError, KeyError, RuntimeError):
            self.node.get_logger().warning(f"client {client.id} on {entry[0]}: not a {TWIST}; dropped")
            return
        pub.publish(msg)
        self.forwarded += 1

    def _decode(self, data: bytes, encoding: str):
        if encoding == "cdr":
            from rclpy.serialization import deserialize_message

            return deserialize_message(data, self.twist)
        d = json.loads(data)
        msg = self.twist()
        for part in ("linear", "angular"):
            for axis in "xyz":
                setattr(getattr(msg, part), axis, float(d.get(part, {}).get(axis, 0.0)))
        return msg


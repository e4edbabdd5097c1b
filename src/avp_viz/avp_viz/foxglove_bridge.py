"""Serve the running graph to Foxglove (or Lichtblick) live over the Foxglove WebSocket protocol (docs/foxglove.md).

``avp demo --foxglove`` / ``avp launch --foxglove`` add a :class:`FoxgloveBridge` node to the ``avp`` process: it
subscribes to the viewer's topics raw (the CDR bytes as they travel on DDS) and logs each message unchanged to a
``foxglove-sdk`` channel of the same name, with the message's ``ros2msg`` definition as its schema (the same
definition the bags embed) and ``cdr`` encoding, stamped with the graph's simulated time (``/clock``). Connect
Foxglove to ``ws://HOST:PORT`` (default ``ws://127.0.0.1:8765``) and open docs/foxglove_layout.json.

Latched topics (``/tf_static``, the lot map) are sent again once a second, so a client that connects after the
graph started still gets them (the WebSocket protocol has no latching). The server binds to loopback unless
``--foxglove-host`` says otherwise: anyone who reaches the port sees the graph's data. It offers no services or
parameters; with driven cars (``drive``) it offers ``clientPublish`` on their ``/avp/driver<j>/cmd_vel`` topics only
(:mod:`avp_viz.foxglove_drive`), else none.
"""

from __future__ import annotations

from rclpy.node import Node

from avp_bag.recorder import GRAPH_TOPICS
from avp_bag.typestore import make_typestore, message_class
from avp_common.qos import QUIET_READER, reader_qos

#: topic -> (type, latched): what the 3-D panel and the plots need (types and latching as the bags record them)
VIEW_TOPICS: dict[str, tuple[str, bool]] = {t: GRAPH_TOPICS[t] for t in (
    "/tf", "/tf_static", "/avp/viz/lot", "/avp/viz/spots", "/avp/viz/scene", "/avp/debug/scan", "/avp/plan",
    "/avp/cmd", "/avp/episode_status")}
LATCH_RESEND = 1.0  # s between re-sends of a latched topic's last message


def view_topics(egos: int = 1) -> dict[str, tuple[str, bool]]:
    """What the viewer gets: :data:`VIEW_TOPICS`, or with several egos the lot's (/tf, /tf_static, episode status)
    and each ego's scene, command and status under /avp/ego<i>/ (docs/world.md, "Several egos")."""
    if egos == 1:
        return dict(VIEW_TOPICS)
    out = {t: GRAPH_TOPICS[t] for t in ("/tf", "/tf_static", "/avp/episode_status")}
    for i in range(egos):
        for t in ("viz/lot", "viz/spots", "viz/scene", "plan", "cmd", "episode_status"):
            out[f"/avp/ego{i}/{t}"] = GRAPH_TOPICS[f"/avp/{t}"]
    return out


class FoxgloveBridge(Node):
    """A foxglove-sdk WebSocket server fed with the graph's topics (see the module docstring)."""

    def __init__(self, port: int = 8765, host: str = "127.0.0.1",
                 topics: dict[str, tuple[str, bool]] | None = None, drive: bool = False) -> None:
        import foxglove

        super().__init__("avp_foxglove")
        topics = view_topics() if topics is None else dict(topics)
        self.drive = None
        if drive:  # Foxglove's Teleop panel may drive the driven cars, and nothing else (foxglove_drive)
            from foxglove.websocket import Capability

            from avp_viz.foxglove_drive import DriveListener

            self.drive = DriveListener(self)
            self.server = foxglove.start_server(name="avp", host=host, port=port,
                                                capabilities=[Capability.ClientPublish],
                                                supported_encodings=["json", "cdr"], server_listener=self.drive)
            self.drive.server = self.server
        else:
            self.server = foxglove.start_server(name="avp", host=host, port=port)
        self.port = self.server.port
        self.clock_ns = 0
        self.latched: dict[str, bytes] = {}
        self.channels = {}
        self.counts: dict[str, int] = {}
        ts = make_typestore()
        for topic, (typename, latched) in topics.items():
            msgdef, _ = ts.generate_msgdef(typename, ros_version=2)
            schema = foxglove.Schema(name=typename, encoding="ros2msg", data=msgdef.encode())
            self.channels[topic] = foxglove.Channel(topic, schema=schema, message_encoding="cdr")
            qos = reader_qos(latched, 10)
            self.create_subscription(message_class(typename), topic, self._forward(topic, latched), qos, raw=True,
                                     event_callbacks=QUIET_READER)
        self.create_subscription(message_class("rosgraph_msgs/msg/Clock"), "/clock", self._on_clock, 10,
                                 event_callbacks=QUIET_READER)
        self._resend = self.create_timer(LATCH_RESEND, self._resend_latched)

    def _on_clock(self, msg) -> None:
        self.clock_ns = int(msg.clock.sec) * 1_000_000_000 + int(msg.clock.nanosec)

    def _forward(self, topic: str, latched: bool):
        channel = self.channels[topic]

        def cb(raw: bytes) -> None:
            channel.log(bytes(raw), log_time=self.clock_ns)
            self.counts[topic] = self.counts.get(topic, 0) + 1
            if latched:
                self.latched[topic] = bytes(raw)

        return cb

    def _resend_latched(self) -> None:
        for topic, raw in self.latched.items():
            self.channels[topic].log(raw, log_time=self.clock_ns)

    def close(self) -> None:
        self.server.stop()


"""Republish a bag into the live graph with its sim clock (`avp replay`).

Messages go out as the recorded CDR bytes (no re-serialisation), in log-time order, paced by
``rate`` (1.0 = as recorded, 0 = as fast as possible), starting ``start_offset`` seconds into the
bag, optionally only for some topics. /clock is republished from the bag (or synthesised from the log
time when the bag has none), so nodes with use_sim_time follow the bag's time. Latched topics are
republished latched.
"""

from __future__ import annotations

import time
from pathlib import Path

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from avp_bringup.bag import make_typestore, message_class


class BagReplayer(Node):
    def __init__(self, bag: Path, topics: list[str] | None = None, node_name: str = "avp_replay") -> None:
        from rosbags.highlevel import AnyReader

        super().__init__(node_name)
        self.bag = Path(bag)
        self.reader = AnyReader([self.bag], default_typestore=make_typestore())
        self.reader.open()
        self.connections = [c for c in self.reader.connections if topics is None or c.topic in topics]
        if topics:
            missing = sorted(set(topics) - {c.topic for c in self.connections})
            if missing:
                raise ValueError(f"{bag}: no topic(s) {missing} in the bag")
        self.pubs = {}
        for c in self.connections:
            qos_list = getattr(c.ext, "offered_qos_profiles", []) or []
            latched = bool(qos_list) and qos_list[0].durability.name == "TRANSIENT_LOCAL"
            qos = QoSProfile(depth=1 if latched else 100, history=HistoryPolicy.KEEP_LAST,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)
            self.pubs[c.topic] = self.create_publisher(message_class(c.msgtype), c.topic, qos)
        self.has_clock = any(c.topic == "/clock" for c in self.connections)
        self.clock_pub = None if self.has_clock else self.create_publisher(Clock, "/clock", 10)
        self.published = 0

    def wait_for_subscribers(self, topics: list[str], timeout: float = 10.0) -> bool:
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout:
            if all(self.pubs[t].get_subscription_count() > 0 for t in topics if t in self.pubs):
                return True
            time.sleep(0.05)
        return False

    def play(self, rate: float = 1.0, start_offset: float = 0.0, spin=None) -> int:
        start = self.reader.start_time + int(start_offset * 1e9)
        wall0 = time.monotonic()
        t_first = None
        for conn, t, raw in self.reader.messages(connections=self.connections, start=start):
            if t_first is None:
                t_first = t
            if rate > 0:
                delay = (t - t_first) / 1e9 / rate - (time.monotonic() - wall0)
                if delay > 0:
                    time.sleep(delay)
            if self.clock_pub is not None:
                self.clock_pub.publish(Clock(clock=_time(t)))
            self.pubs[conn.topic].publish(bytes(raw))
            self.published += 1
            if spin is not None:
                spin()
        self.wait_for_acks()
        return self.published

    def wait_for_acks(self, timeout: float = 5.0) -> bool:
        """Reliable delivery needs the publisher alive until subscribers acknowledged every message."""
        from rclpy.duration import Duration

        return all(pub.wait_for_all_acked(Duration(seconds=timeout)) for pub in self.pubs.values())

    def close(self) -> None:
        self.reader.close()


def _time(ns: int):
    from builtin_interfaces.msg import Time

    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

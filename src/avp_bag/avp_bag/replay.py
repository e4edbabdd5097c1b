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

from avp_bag.typestore import message_class


class BagReplayer(Node):
    """Republishes ``bag`` (read by :class:`avp_bag.reader.BagReader`: a damaged split is read up to its
    damage or refused with one error naming the file; a topic of a type not installed is skipped with a
    warning unless asked for by name)."""

    def __init__(self, bag: Path, topics: list[str] | None = None, node_name: str = "avp_replay") -> None:
        from avp_bag.reader import BagReader, BagReadError

        self.bag = Path(bag)
        self.reader = BagReader(self.bag)
        if topics:
            missing = sorted(set(topics) - set(self.reader.topics))
            if missing:
                raise BagReadError(f"{bag}: no topic(s) {missing} of a known type in the bag")
        self.topics = [t for t in self.reader.topics.values() if topics is None or t.name in topics]
        super().__init__(node_name)
        self.pubs = {}
        for t in self.topics:
            qos = QoSProfile(depth=1 if t.latched else 100, history=HistoryPolicy.KEEP_LAST,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL if t.latched else DurabilityPolicy.VOLATILE)
            self.pubs[t.name] = self.create_publisher(message_class(t.msgtype), t.name, qos)
        self.connections = self.topics  # the topics replayed (kept under its old name for callers)
        self.has_clock = "/clock" in self.pubs
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
        wall0 = time.monotonic()
        t_first = None
        for topic, _type, t, raw in self.reader.messages(self.pubs):
            if t_first is None:
                t_first = t
            if t < t_first + int(start_offset * 1e9):
                continue
            if rate > 0:
                delay = (t - t_first - int(start_offset * 1e9)) / 1e9 / rate - (time.monotonic() - wall0)
                if delay > 0:
                    time.sleep(delay)
            if self.clock_pub is not None:
                self.clock_pub.publish(Clock(clock=_time(t)))
            self.pubs[topic].publish(raw)
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
        """Nothing to release: the reader opens each split only while it reads it."""


def _time(ns: int):
    from builtin_interfaces.msg import Time

    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

"""Record the graph to rosbag2 (MCAP by default) with `rosbags` (metrics from a bag: :mod:`avp_bag.episode`).

rosbag2/ros2 bag are not on PyPI here; `rosbags` writes standard rosbag2 directories (metadata.yaml +
storage file) with the message definitions embedded, so Foxglove/Lichtblick and rosbags readers decode
the custom avp_msgs types. The writer (:class:`avp_bag.writer.SplitBagWriter`) is opened and
closed explicitly (never inside `with`): Ctrl-C / SIGTERM close it cleanly, and it finishes a storage file
("split": summary, index, footer, metadata.yaml rewritten atomically) every ``split_period`` wall seconds,
so a SIGKILLed recorder leaves a bag that reads back up to its last finished split. A full disk stops the
recorder with one error (``BagRecorder.error``); the bag stays readable and the graph goes on.
"""

from __future__ import annotations

import time
from pathlib import Path

from rclpy.node import Node
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

from avp_bag.typestore import make_typestore, message_class
from avp_bag.writer import BagStorageError, SplitBagWriter
from avp_common.conversions import time_to_ns
from avp_common.drain import draining_subscription
from avp_common.qos import GROUND_TRUTH, reader_qos

#: topic -> (type, latched). The default recording set of the graph (the simulator's ground-truth markers, the
#: belief grid and the BEVs are left out: derivable or large).
GRAPH_TOPICS: dict[str, tuple[str, bool]] = {
    "/clock": ("rosgraph_msgs/msg/Clock", False),
    "/avp/lot_map": ("avp_msgs/msg/LotMap", True),
    "/avp/observation": ("avp_msgs/msg/Observation", False),
    "/avp/cmd": ("geometry_msgs/msg/TwistStamped", False),
    "/avp/episode_status": ("avp_msgs/msg/EpisodeStatus", True),
    "/avp/debug/ground_truth": ("avp_msgs/msg/GroundTruth", False),
    "/avp/beliefs": ("avp_msgs/msg/SpotBeliefs", False),
    "/avp/intentions": ("avp_msgs/msg/IntentionArray", False),
    "/avp/ego_intention": ("avp_msgs/msg/IntentionArray", False),  # the implicit method's (belief node's ego_intent)
    "/avp/predictions": ("avp_msgs/msg/PredictedTrajectoryArray", False),
    "/avp/decision": ("avp_msgs/msg/PlannerDecision", False),
    "/avp/avp_planner/debug/decision": ("avp_msgs/msg/DecisionTrace", False),  # why the ego stands (the decision trace)
    "/avp/plan": ("nav_msgs/msg/Path", False),
    # what a viewer needs (docs/foxglove.md): transforms, the scene node's markers, the ray scan
    "/tf": ("tf2_msgs/msg/TFMessage", False),
    "/tf_static": ("tf2_msgs/msg/TFMessage", True),
    "/avp/viz/lot": ("visualization_msgs/msg/MarkerArray", True),
    "/avp/viz/spots": ("visualization_msgs/msg/MarkerArray", True),
    "/avp/viz/scene": ("visualization_msgs/msg/MarkerArray", False),
    "/avp/debug/scan": ("sensor_msgs/msg/LaserScan", False),
    # noisy sensing (docs/perception.md): the simulator's frame and raw detections, the tracker's tracks
    "/avp/sensing/observation": ("avp_msgs/msg/Observation", False),
    "/avp/sensing/detections": ("autoware_perception_msgs/msg/DetectedObjects", False),
    "/avp/tracking/objects": ("autoware_perception_msgs/msg/TrackedObjects", False),
    "/avp/viz/detections": ("visualization_msgs/msg/MarkerArray", False),
    "/avp/viz/tracks": ("visualization_msgs/msg/MarkerArray", False),
}
OPTIONAL_TOPICS = {
    "/avp/debug/markers": ("visualization_msgs/msg/MarkerArray", False),  # the simulator's ground-truth view
    "/avp/debug/occupancy": ("nav_msgs/msg/OccupancyGrid", False),  # belief map b_t (derivable from beliefs)
    "/avp/debug/bev": ("sensor_msgs/msg/Image", False),  # the belief node's BEVs (large)
}


#: an ego's own topics (under /avp/ego<i>/ in a graph of several egos)
EGO_TOPICS = ("observation", "cmd", "episode_status", "beliefs", "intentions", "ego_intention", "predictions",
              "decision", "avp_planner/debug/decision", "plan", "viz/lot", "viz/spots", "viz/scene")


def fleet_topics(egos: int) -> dict[str, tuple[str, bool]]:
    """The recording set of a graph of ``egos`` egos (avp launch --egos K): the lot's topics (clock, lot map, ground
    truth, the lot's episode status, /tf) and every ego's own under /avp/ego<i>/. One ego: :data:`GRAPH_TOPICS`."""
    if egos == 1:
        return dict(GRAPH_TOPICS)
    own = {f"/avp/{t}" for t in EGO_TOPICS}
    out = {t: v for t, v in GRAPH_TOPICS.items() if t not in own or t == "/avp/episode_status"}
    out.pop("/avp/debug/scan", None)  # the simulator's scan is ego 0's in a one-ego graph only
    for i in range(egos):
        out.update({f"/avp/ego{i}/{t}": GRAPH_TOPICS[f"/avp/{t}"] for t in EGO_TOPICS})
        # what ego i's planner hears over the V2V channel (avp_planner.v2v_node)
        out[f"/avp/ego{i}/v2v/beacons"] = ("avp_msgs/msg/EgoBeaconArray", False)
    return out


def _qos(latched: bool) -> Qos:
    zero = QosTime(0, 0)
    return Qos(QosHistory.KEEP_LAST, 1 if latched else 100, QosReliability.RELIABLE,
               QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE, zero, zero,
               QosLiveliness.AUTOMATIC, zero, False)


#: topics whose messages the graph's nodes tag (avp_common.msg_auth): by default only tagged ones are recorded
TAGGED_TOPICS = frozenset({"/avp/lot_map", "/avp/observation", "/avp/v2v/beacons", "/avp/cmd", "/avp/beliefs",
                           "/avp/intentions", "/avp/ego_intention", "/avp/predictions", "/avp/sensing/observation",
                           "/avp/sensing/detections", "/avp/tracking/objects"})


class BagRecorder(Node):
    """Raw (CDR) subscriptions written straight into a rosbag2; log time = latest /clock (sim time).

    ``foreign``: also record messages on :data:`TAGGED_TOPICS` that do not carry the graph's tag. Off by default:
    the bag is the episode the graph ran, and a flood from another process (docs/bad_input.md row 48) is counted in one
    log line a second instead of being written at its rate (which cost this process more CPU than the flooder).

    ``warn_unmatched_after``: a reader that has matched no writer for this many seconds while the graph shows a writer
    of its topic (incompatible QoS, most often) is named in one warning: its messages are not recorded. The readers
    have no QoS event handlers (``avp_common.qos.QUIET_READER``: with about 45 readers they cost most of the process's
    CPU), so this check is what tells of such a writer.
    """

    def __init__(self, out: Path, topics: dict[str, tuple[str, bool]] | None = None, storage: str = "mcap",
                 node_name: str = "avp_recorder", split_period: float = 1.0, foreign: bool = False,
                 warn_unmatched_after: float = 10.0) -> None:
        from avp_common.msg_auth import load_key
        from avp_common.ratelog import RateLimitedLog

        super().__init__(node_name)
        self.key = None if foreign else load_key()
        self.foreign_dropped: dict[str, int] = {}
        self._foreign_log = RateLimitedLog(self.get_logger().warning)
        self.out = Path(out)
        topics = dict(GRAPH_TOPICS if topics is None else topics)
        self.ts = make_typestore()
        self.writer = SplitBagWriter(self.out, storage, split_period)
        self.writer.open()
        # finish the open split also when no message arrives (e.g. after the episode ended)
        self._rotate_timer = self.create_timer(min(0.25, split_period / 2), self._rotate)
        self.warn_unmatched_after = float(warn_unmatched_after)
        self._unmatched_since: dict[str, float] = {}
        self.warned_unmatched: set[str] = set()  # topics named in the warning (each once)
        self._match_timer = self.create_timer(1.0, self._watch_matches)
        self.closed = False
        self.error: str | None = None  # set when the file system failed and recording stopped
        self.clock_ns = 0
        self.counts: dict[str, int] = {}
        self._subs: dict[str, object] = {}
        for topic, (typename, latched) in topics.items():
            conn = self.writer.add_connection(topic, typename, typestore=self.ts, offered_qos_profiles=[_qos(latched)])
            # reader queue as deep as the ground-truth writer keeps (30 s of steps): a recorder stalled on a split
            # or an fsync drops nothing
            qos = reader_qos(latched, GROUND_TRUTH.depth)
            # bursts (a flood) are taken in one executor round (avp_common.drain)
            self._subs[topic] = draining_subscription(self, message_class(typename), topic,
                                                      self._callback(topic, conn), qos)

    def unmatched(self, required: tuple[str, ...] = ()) -> list[str]:
        """Recorded topics whose reader has matched no writer yet although one is due: the topic is in ``required`` or
        the graph already shows a publisher of it. A volatile reader that matches after the episode started never
        gets the messages sent before (on a loaded machine matching can lag discovery by seconds), so a graph is
        started only once this is empty (avp_bringup.demo)."""
        return [t for t, sub in self._subs.items()
                if sub.get_publisher_count() == 0 and (t in required or self.count_publishers(t) > 0)]

    def _watch_matches(self) -> None:
        """Name each reader that has matched no writer for :attr:`warn_unmatched_after` s while the graph shows one."""
        now = time.monotonic()
        late = set(self.unmatched())
        self._unmatched_since = {t: self._unmatched_since.get(t, now) for t in late}
        due = sorted(t for t, t0 in self._unmatched_since.items()
                     if now - t0 >= self.warn_unmatched_after and t not in self.warned_unmatched)
        if due:
            self.warned_unmatched.update(due)
            self.get_logger().warning(
                f"no writer of {', '.join(due)} has matched this recorder's reader in {self.warn_unmatched_after:g} s "
                "although the graph shows one (incompatible QoS?): its messages are not recorded")

    def _callback(self, topic, conn):
        from avp_common.msg_auth import ego_scope, scoped_key, verify

        is_clock = topic == "/clock"
        scope = ego_scope(topic)  # several egos: ego i's topics carry ego i's tag (avp_common.msg_auth)
        check = self.key is not None and ("/avp/" + topic.split("/", 3)[-1] if scope else topic) in TAGGED_TOPICS
        key = scoped_key(self.key, scope) if self.key is not None else None

        def cb(raw: bytes) -> None:
            if self.closed:
                return
            if check and not verify(key, raw):
                n = self.foreign_dropped[topic] = self.foreign_dropped.get(topic, 0) + 1
                self._foreign_log.report(topic, f"{topic}: {n} message(s) without the graph's tag not recorded "
                                                "(another publisher; `avp record --foreign` records them)")
                return
            if is_clock:
                msg = self.ts.deserialize_cdr(raw, "rosgraph_msgs/msg/Clock")
                self.clock_ns = int(msg.clock.sec) * 1_000_000_000 + int(msg.clock.nanosec)
            try:
                self.writer.write(conn, self.clock_ns, raw)
            except BagStorageError as exc:
                self._stop(exc)
                return
            self.counts[topic] = self.counts.get(topic, 0) + 1

        return cb

    def _rotate(self) -> None:
        if not self.closed:
            try:
                self.writer.maybe_rotate()
            except BagStorageError as exc:
                self._stop(exc)

    def _stop(self, exc: BagStorageError) -> None:
        """The file system failed (disk full, ...): stop recording with one error; the node and graph go on."""
        self.closed = True
        self.error = str(exc)
        self.get_logger().error(f"recording stopped: {exc}")

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            try:
                self.writer.close()
            except BagStorageError as exc:
                self.error = str(exc)
                self.get_logger().error(f"recording stopped: {exc}")


__all__ = ["BagRecorder", "GRAPH_TOPICS", "TAGGED_TOPICS", "OPTIONAL_TOPICS", "fleet_topics", "time_to_ns"]

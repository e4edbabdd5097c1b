"""The simulator's topics of each ego (docs/world.md, "Several egos").

One ego (K = 1, the paper): ``observation``, ``cmd`` and ``episode_status`` in the simulator's namespace, as always.
K egos: ego i's are ``ego<i>/observation`` (tagged with ego i's key, :func:`avp_common.msg_auth.scoped_key`),
``ego<i>/cmd`` (only a command tagged with ego i's key steers ego i) and ``ego<i>/episode_status`` (its own status and
metrics), beside the lot's ``episode_status``. Ego i's pipeline runs in namespace ``/avp/ego<i>`` and finds them by
their relative names (avp_bringup.graph.fleet_graph).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from geometry_msgs.msg import TwistStamped

from avp_common.qos import QUIET_READER, QUIET_WRITER, STATUS, STEP, STEP_INPUT
from avp_msgs.msg import EpisodeStatus, Observation

#: the most egos one simulator drives (egos.count)
MAX_EGOS = 8


def ego_prefix(index: int, count: int) -> str:
    """The relative topic prefix of ego ``index`` among ``count`` egos: '' for one ego, else ``ego<i>/``."""
    return "" if count == 1 else f"ego{index}/"


@dataclass
class EgoChannel:
    """Ego ``index``'s publishers and command subscription, and the commands it has sent."""

    index: int
    pub_obs: Any
    sub_cmd: Any
    pub_status: Any | None  # None for one ego: the lot's episode_status is its own
    latest_cmd: tuple[float, float, float, int] | None = None  # real time: (v, omega, wall time, stamp ns)
    pending: tuple[float, float] | None = None  # lock-step: the command answering the current step
    holding_since: int | None = None  # real time: step the ego began holding still (no command)
    started_moving: bool = False  # real time: its first command came

    @property
    def cmd_topic(self) -> str:
        return self.sub_cmd.topic_name

    def reset(self) -> None:
        self.latest_cmd, self.pending, self.holding_since, self.started_moving = None, None, None, False


@dataclass
class DriverChannel:
    """Driven car j's command subscription (``driver<j>/cmd_vel``, Twist or TwistStamped; docs/teleop.md) and its
    newest command with the wall time it came."""

    index: int  # j
    slot: int  # its slot in the world's cars (K + j)
    sub: Any
    pub_status: Any = None  # driver<j>/episode_status: its own metrics (interrupted steps it caused, collisions)
    latest: tuple[float, float, float] | None = None  # (v, omega, wall time)

    def command(self, now: float, watchdog: float) -> tuple[float, float]:
        """The newest command, or a stop when it is older than ``watchdog`` s (or none came)."""
        if self.latest is None or now - self.latest[2] > watchdog:
            return 0.0, 0.0
        return self.latest[0], self.latest[1]


def make_drivers(node, count: int, n_egos: int, stamped: bool,
                 on_cmd: Callable[[int, float, float], None]) -> list[DriverChannel]:
    """The ``count`` driven cars' subscriptions: best effort, so that reliable and best-effort publishers (a
    teleop node, Foxglove's bridge) both match; untagged (a person's keyboard or viewer, not the pipeline)."""
    from geometry_msgs.msg import Twist
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    qos = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.BEST_EFFORT)

    def callback(j: int):
        def cb(m) -> None:
            t = m.twist if stamped else m
            on_cmd(j, float(t.linear.x), float(t.angular.z))
        return cb

    out = []
    for j in range(count):
        sub = node.create_subscription(TwistStamped if stamped else Twist, f"driver{j}/cmd_vel", callback(j), qos,
                                       event_callbacks=QUIET_READER)
        out.append(DriverChannel(j, n_egos + j, sub,
                                 node.create_publisher(EpisodeStatus, f"driver{j}/episode_status", STATUS,
                                                       event_callbacks=QUIET_WRITER)))
    return out


class DriverTypeCheck:
    """Names, once each, a publisher on a driven car's ``cmd_vel`` of the other message type (``Twist`` where
    ``drivers.stamped: true`` reads ``TwistStamped``, or the reverse): such a writer matches no reader, and neither
    side is told (Fast DDS fires no incompatible-type event, rclpy's default handlers or not), so the car would just
    stand. Checked every ``period`` s on the node's graph (a timer of ``node``); :attr:`warned` holds what was named."""

    def __init__(self, node, drivers: list[DriverChannel], stamped: bool, period: float = 1.0) -> None:
        self.node, self.drivers = node, drivers
        self.want = "geometry_msgs/msg/TwistStamped" if stamped else "geometry_msgs/msg/Twist"
        self.stamped = bool(stamped)
        self.warned: set[tuple[str, str, str]] = set()  # (topic, publisher node, its type)
        self.timer = node.create_timer(period, self.check)

    def check(self) -> None:
        for d in self.drivers:
            topic = d.sub.topic_name
            for info in self.node.get_publishers_info_by_topic(topic):
                who = f"{info.node_namespace.rstrip('/')}/{info.node_name}"
                key = (topic, who, info.topic_type)
                if info.topic_type != self.want and key not in self.warned:
                    self.warned.add(key)
                    self.node.get_logger().warning(
                        f"{topic}: {who} publishes {info.topic_type}, but the simulator reads {self.want} "
                        f"(drivers.stamped: {str(self.stamped).lower()}): its commands never arrive")


def make_channels(node, auth, count: int, on_cmd: Callable[[int, TwistStamped], None],
                  observation: str = "observation") -> list[EgoChannel]:
    """The ``count`` egos' channels of the simulator ``node`` (with its Authenticator ``auth``); ``observation``:
    the topic of each ego's observation (``sensing/observation`` with noisy sensing: the tracker's input)."""
    if not 1 <= count <= MAX_EGOS:
        raise ValueError(f"parameter 'egos.count': {count}: between 1 and {MAX_EGOS} egos")
    channels = []
    for i in range(count):
        pre = ego_prefix(i, count)
        ego = None if count == 1 else i
        channels.append(EgoChannel(
            index=i,
            pub_obs=auth.publisher(Observation, pre + observation, STEP, ego=ego),
            sub_cmd=auth.subscription(TwistStamped, pre + "cmd", (lambda m, i=i: on_cmd(i, m)), STEP_INPUT),
            pub_status=node.create_publisher(EpisodeStatus, pre + "episode_status", STATUS,
                                             event_callbacks=QUIET_WRITER) if count > 1 else None,
        ))
    return channels

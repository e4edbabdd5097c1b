"""scripted_driver node: a stand-in ego controller until the Hybrid A* planner lands.

Subscribes lot_map (latched) and observation; publishes cmd (TwistStamped stamped like the
observation it answers, so the simulator's lock-step matches it). Never reads ground truth.
"""

from __future__ import annotations

import sys

from geometry_msgs.msg import TwistStamped
from rclpy.node import Node

from avp_common.conversions import MessageError, lot_from_msg_or_log, observation_from_msg
from avp_common.msg_auth import Authenticator, episode_of, with_episode
from avp_common.node_main import run_node
from avp_common.params import ParamSpec, declare_and_validate
from avp_common.qos import LATCHED, STEP
from avp_msgs.msg import LotMap, Observation
from avp_planner.scripted_driver import ScriptedDriver, ScriptedDriverConfig

DRIVER_PARAMS = [
    ParamSpec("speed", float, "Cruise speed of the scripted ego.", "v", "eq. (1)", min=0.0, max=5.0, default=1.5),
    ParamSpec("lookahead", float, "Pure-pursuit look-ahead distance.", min=0.5, default=4.0),
    ParamSpec("stop_distance", float, "Stop when an observed vehicle is this close ahead.", min=0.0, default=6.0),
    ParamSpec("corridor_half_width", float, "Half width of the corridor checked ahead.", min=0.0, default=1.6),
    ParamSpec("road_end_margin", float, "Stop this far before the end of the followed road.", min=0.0,
              default=4.0),
]


class ScriptedDriverNode(Node):
    def __init__(self) -> None:
        super().__init__("scripted_driver")
        p = declare_and_validate(self, DRIVER_PARAMS)
        self.config = ScriptedDriverConfig(**p)
        self.driver: ScriptedDriver | None = None
        self.pending: Observation | None = None
        self.auth = Authenticator(self)  # tagged cmd; lot_map and observation only from holders of the key
        self.pub = self.auth.publisher(TwistStamped, "cmd", STEP)
        self.auth.subscription(LotMap, "lot_map", self._on_lot, LATCHED)
        self.sub_obs = self.auth.subscription(Observation, "observation", self._on_obs, STEP)

    def _on_lot(self, msg: LotMap) -> None:
        lot = lot_from_msg_or_log(msg, self.get_logger())
        if lot is None:
            return
        self.driver = ScriptedDriver(lot, self.config)
        if self.pending is not None:
            self._on_obs(self.pending)

    def _on_obs(self, msg: Observation) -> None:
        if self.driver is None:
            self.pending = msg
            return
        try:
            obs = observation_from_msg(msg)
        except MessageError as exc:
            self.get_logger().error(f"{self.sub_obs.topic_name}: {exc}; message dropped")
            return
        v, om = self.driver.command(obs)
        cmd = TwistStamped()
        cmd.header.stamp = msg.header.stamp
        cmd.header.frame_id = with_episode("ego", episode_of(msg.header.frame_id))  # the observation's episode
        cmd.twist.linear.x = float(v)
        cmd.twist.angular.z = float(om)
        self.pub.publish(cmd)  # tagged (avp_common.msg_auth)


def main(args=None) -> int:
    return run_node(ScriptedDriverNode, "scripted_driver", args)


if __name__ == "__main__":
    sys.exit(main())

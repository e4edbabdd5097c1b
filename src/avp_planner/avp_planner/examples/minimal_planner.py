"""A minimal planner of your own, plugged into the AVP graph (docs/custom_planner.md).

The topic contract (namespace /avp, relative names):

* subscribe ``observation`` (avp_msgs/Observation, reliable, volatile, depth 10) — everything the ego
  senses at step k (§III-A); optionally ``lot_map`` (avp_msgs/LotMap, reliable + transient_local),
  ``beliefs`` and ``predictions``;
* publish ``cmd`` (geometry_msgs/TwistStamped: v = twist.linear.x [m/s], ω = twist.angular.z [rad/s]),
  **one per observation, with header.stamp = the observation's stamp** — in lock-step the simulator waits
  for exactly that stamp; in real time it uses a command only if it answers the current observation;
* be a lifecycle node, so that ``avp swap-planner --node /avp/<name>`` can configure and activate it
  and deactivate the planner it replaces: publish nothing while inactive, and on activation answer the
  newest observation received while inactive (in lock-step the simulator is waiting for it).

This one drives straight ahead at ``speed`` and stops while an observed vehicle is within
``stop_distance`` ahead in a corridor of ``corridor_half_width``: enough to see the contract at work, not
a parking planner. Run it with ``ros2 run avp_planner minimal_planner --ros-args -r __ns:=/avp
--params-file <share>/avp_planner/config/minimal_planner.param.yaml`` (or see the doc for `avp`).
"""

from __future__ import annotations

import math
import sys

import rclpy
from geometry_msgs.msg import TwistStamped
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from avp_common.lifecycle import guard_lifecycle_services
from avp_common.msg_auth import episode_of, load_key, sign, with_episode
from avp_common.node_main import run_node
from avp_common.params import ParamSpec, declare_and_validate
from avp_common.qos import STEP
from avp_msgs.msg import Observation

MINIMAL_PARAMS = [
    ParamSpec("speed", float, "Forward speed of the example planner.", "v", "eq. (1)", min=0.0, max=5.0,
              default=0.5),
    ParamSpec("stop_distance", float, "Stop while an observed vehicle is this close ahead.", min=0.0, default=6.0),
    ParamSpec("corridor_half_width", float, "Half width of the corridor checked ahead.", min=0.0, default=1.5),
]


class MinimalPlanner(LifecycleNode):
    def __init__(self) -> None:
        super().__init__("minimal_planner")
        guard_lifecycle_services(self)  # an impossible transition request is answered, not fatal
        self.p = declare_and_validate(self, MINIMAL_PARAMS)  # one-line error and exit on a bad value
        self.active = False
        self.latest: Observation | None = None  # newest observation (answered on activation)
        # a lifecycle publisher publishes only while the node is active
        self.pub_cmd = self.create_lifecycle_publisher(TwistStamped, "cmd", STEP)
        self.key = load_key()  # the user's key: this planner's commands are tagged with it (avp_common.msg_auth)
        self.sub_obs = self.create_subscription(Observation, "observation", self._on_obs, STEP)

    # lifecycle: configure/activate/deactivate/shutdown (avp swap-planner drives these)
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = True
        self.get_logger().info("activated")
        ret = super().on_activate(state)  # enables the lifecycle publisher
        if self.latest is not None:
            self._answer(self.latest)
        return ret

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        return super().on_deactivate(state)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        self._exit = self.create_timer(0.2, lambda: rclpy.try_shutdown())  # exit after replying
        return TransitionCallbackReturn.SUCCESS

    def _on_obs(self, msg: Observation) -> None:
        self.latest = msg
        if self.active:
            self._answer(msg)

    def _answer(self, msg: Observation) -> None:
        v = self.p["speed"]
        x, y, th = msg.ego_pose.x, msg.ego_pose.y, msg.ego_pose.theta
        if not all(math.isfinite(a) for a in (x, y, th)):
            self.get_logger().error(f"{self.sub_obs.topic_name} step {msg.step}: NaN/inf ego pose; holding still")
            v = 0.0
        for veh in msg.vehicles:
            if not veh.history:
                continue
            dx, dy = veh.history[-1].x - x, veh.history[-1].y - y
            ahead = dx * math.cos(th) + dy * math.sin(th)
            side = -dx * math.sin(th) + dy * math.cos(th)
            if 0.0 < ahead < self.p["stop_distance"] and abs(side) < self.p["corridor_half_width"]:
                v = 0.0
        cmd = TwistStamped()
        cmd.header.stamp = msg.header.stamp  # the stamp of the observation this command answers
        cmd.header.frame_id = with_episode("ego", episode_of(msg.header.frame_id))  # ... and its episode
        cmd.twist.linear.x = float(v)
        cmd.twist.angular.z = 0.0
        self.pub_cmd.publish(sign(self.key, cmd))  # the simulator takes only tagged commands (avp_common.msg_auth)


def main(args=None) -> int:
    return run_node(MinimalPlanner, "minimal_planner", args)


if __name__ == "__main__":
    sys.exit(main())

"""method_ego node: one Table I method as the ego of the live graph (``avp launch|demo --method NAME``,
``avp experiment --transport ros``) — the thin ROS wrapper around :class:`avp_bringup.experiment.ego.MethodEgo`.

Subscribes lot_map (latched) and observation; for every observation publishes beliefs (SpotBeliefs, when
the method uses a belief map), predictions (PredictedTrajectoryArray, the other agents' trajectories of
§V-C), decision (PlannerDecision; its spot_selection_time includes the perception of the method) and
finally cmd (TwistStamped stamped like the observation). In lock-step an observation with step 0 starts a
new episode (the core is reset); the same step again (a re-sent observation) gets the same command again.
Never reads ground truth.

The method runs in one process here; the per-stage nodes of #4 (belief, prediction) + the planner node are
configured from the same profile (its ``perception`` and ``planner`` blocks) once they exist.
"""

from __future__ import annotations

import sys

from geometry_msgs.msg import TwistStamped
from rclpy.node import Node

from avp_common.conversions import (
    MessageError,
    beliefs_to_msg,
    lot_from_msg,
    observation_from_msg,
    predictions_to_msg,
)
from avp_common.node_main import run_node
from avp_common.params import ParamSpec, declare_and_validate
from avp_common.qos import LATCHED, STEP
from avp_msgs.msg import LotMap, Observation, PlannerDecision, PredictedTrajectoryArray, SpotBeliefs

METHOD_NODE_PARAMS = [
    ParamSpec("method", str, "Method profile: a name in avp_bringup/config/methods/ (bezier, constant_velocity, "
              "hybrid_astar, implicit, nawaz) or a profile file.", "", "§VI-B", default="bezier"),
    ParamSpec("deterministic", bool, "Lift the wall-clock caps of the planner and the Hybrid A* predictor so that "
              "iteration caps alone end searches (avp experiment).", "", "§VI-B", default=False),
    ParamSpec("intent_weights", str, "Intent CNN state-dict file; empty = the shipped weights if present, else "
              "seeded random weights.", "", "§V-A", default=""),
    ParamSpec("intent_seed", int, "Seed of the random intent weights.", "", "§V-A", min=0, max=2**31 - 1, default=0),
    ParamSpec("message_precision", bool, "Round intention probabilities and beliefs to float32 as the per-stage "
              "nodes' messages do.", default=True),
    ParamSpec("torch_threads", int, "torch.set_num_threads (1: deterministic and fastest on a shared CPU).",
              min=1, max=64, default=1),
]
MODES = {"idle": PlannerDecision.MODE_IDLE, "park": PlannerDecision.MODE_PARK, "explore": PlannerDecision.MODE_EXPLORE}


class MethodEgoNode(Node):
    def __init__(self) -> None:
        super().__init__("method_ego")
        self.p = declare_and_validate(self, METHOD_NODE_PARAMS)
        import torch

        from avp_bringup.experiment.profiles import load_profile

        torch.set_num_threads(self.p["torch_threads"])
        self.profile = load_profile(self.p["method"])  # ProfileError (a ValueError) stops start-up with one line
        if not self.profile.available:
            raise ValueError(f"method {self.profile.name!r} is not available: {self.profile.unavailable_reason}")
        self.ego = None
        self.lot = None
        self.pending: Observation | None = None
        self.last_step: int | None = None
        self.last_cmd: tuple[float, float] | None = None
        self.pub_cmd = self.create_publisher(TwistStamped, "cmd", STEP)
        self.pub_decision = self.create_publisher(PlannerDecision, "decision", STEP)
        self.pub_beliefs = self.create_publisher(SpotBeliefs, "beliefs", STEP)
        self.pub_preds = self.create_publisher(PredictedTrajectoryArray, "predictions", STEP)
        self.create_subscription(LotMap, "lot_map", self._on_lot, LATCHED)
        self.sub_obs = self.create_subscription(Observation, "observation", self._on_obs, STEP)
        self.get_logger().info(f"method '{self.profile.name}' ({self.profile.label}) from {self.profile.source}")

    def _on_lot(self, msg: LotMap) -> None:
        from avp_bringup.experiment.ego import MethodEgo

        try:
            self.lot = lot_from_msg(msg)
        except ValueError as exc:
            self.get_logger().error(f"lot_map: {exc}")
            return
        self.ego = MethodEgo(self.lot, self.profile, deterministic=self.p["deterministic"],
                             intent_weights=self.p["intent_weights"], intent_seed=self.p["intent_seed"],
                             message_precision=self.p["message_precision"])
        self.get_logger().info(self.ego.intent_info)
        self.last_step = None
        if self.pending is not None:
            msg, self.pending = self.pending, None
            self._on_obs(msg)

    def _on_obs(self, msg: Observation) -> None:
        if self.ego is None:
            self.pending = msg  # answered once the lot map is known
            return
        k = int(msg.step)
        if k == self.last_step and k != 0 and self.last_cmd is not None:
            self._publish_cmd(msg.header.stamp, *self.last_cmd)  # a re-sent observation: the same answer
            return
        if self.last_step is not None and 0 < k < self.last_step:
            self.get_logger().warning(f"{self.sub_obs.topic_name}: step {k} is older than step {self.last_step}; "
                                      "dropped")
            return
        if k == 0:
            self.ego.reset()  # a new episode
        try:
            obs = observation_from_msg(msg)
            out = self.ego.step(obs)
        except (MessageError, ValueError) as exc:
            self.get_logger().error(f"{self.sub_obs.topic_name} step {k}: {exc}; holding still")
            self._publish_cmd(msg.header.stamp, 0.0, 0.0)
            return
        dt = float(obs.dt)
        if out.beliefs is not None:
            self.pub_beliefs.publish(beliefs_to_msg(k, dt, self.lot.spot_ids, out.beliefs))
        self.pub_preds.publish(predictions_to_msg(k, dt, out.predictions))
        self.pub_decision.publish(self._decision_msg(msg, out))
        self.last_step, self.last_cmd = k, out.command
        self._publish_cmd(msg.header.stamp, *out.command)

    def _decision_msg(self, obs_msg: Observation, out) -> PlannerDecision:
        d = out.decision
        msg = PlannerDecision()
        msg.header.stamp = obs_msg.header.stamp
        msg.header.frame_id = "map"
        msg.step = obs_msg.step
        msg.mode = MODES.get(d.mode, PlannerDecision.MODE_IDLE)
        msg.spot_id = int(d.spot_id)
        if d.goal is not None and len(d.goal) == 3:
            msg.goal.x, msg.goal.y, msg.goal.theta = (float(x) for x in d.goal)
        msg.n_candidates = int(d.n_candidates)
        msg.spot_selection_time = float(out.timings["spot_selection_time"])
        msg.path_planning_time = float(out.timings["path_planning_time"])
        msg.reason = str(d.reason)
        return msg

    def _publish_cmd(self, stamp, v: float, om: float) -> None:
        cmd = TwistStamped()
        cmd.header.stamp = stamp
        cmd.header.frame_id = "ego"
        cmd.twist.linear.x, cmd.twist.angular.z = float(v), float(om)
        self.pub_cmd.publish(cmd)


def main(args=None) -> int:
    return run_node(MethodEgoNode, "method_ego", args)


if __name__ == "__main__":
    sys.exit(main())

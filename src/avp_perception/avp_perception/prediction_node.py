"""avp_perception prediction node: the thin ROS wrapper around the trajectory predictors of §V-C.

Topics (relative; the launcher puts every node in namespace /avp):
  subscribes lot_map (latched), observation, intentions (from the belief node)
  publishes  predictions (avp_msgs/PredictedTrajectoryArray, stamped like the observation it answers)

``method``: ``bezier`` (the paper's intention-conditioned cubic Bezier curves, eqs. 9-12), ``constant_velocity``,
``hybrid_astar`` (paths to the intended goals planned with the ego planner's Hybrid A*) or ``learned``
(ParkPredict+'s trajectory transformer conditioned on the same goals, ``learned.*``; the node logs which
weights it runs); pedestrians are always predicted at constant velocity. Each trajectory carries its intention's
probability, spot id and goal.

Lock-step: the observation and the intentions of step k are matched by step (either may come first) and
answered once; an observation of a step already answered (re-sent by the simulator) gets the same message
again. An observation of a later episode (the episode id in its tag) starts a new episode: buffered
messages of another episode are dropped; one of an earlier episode, or of a step lower than the last one answered
(step 0 included), is dropped with a warning (avp_common.step_answers). A malformed message — NaN/inf, unknown spot
ids, probabilities outside [0, 1], a header
stamp that is not step * dt, intentions stamped unlike their observation — is dropped with one error
naming the topic; the node keeps running.
"""

from __future__ import annotations

import sys

from rclpy.node import Node

from avp_common.conversions import (
    MessageError,
    check_stamp,
    lot_from_msg_or_log,
    observation_from_msg,
    predictions_to_msg,
    time_to_ns,
)
from avp_common.msg_auth import Authenticator, episode_of, with_episode
from avp_common.node_main import run_node
from avp_common.params import declare_and_validate
from avp_common.qos import LATCHED, STEP, STEP_INPUT
from avp_common.ratelog import RateLimitedLog
from avp_common.step_answers import StepAnswers
from avp_msgs.msg import IntentionArray, LotMap, Observation, PredictedTrajectoryArray
from avp_perception.conversions import intentions_from_msg
from avp_perception.params import PREDICTION_PARAMS, prediction_config
from avp_predictors.prediction import make_predictor


class PredictionNode(Node):
    def __init__(self, **node_options) -> None:
        """``node_options``: rclpy Node keywords (``cli_args``, ``use_global_arguments``), as a component container
        (avp_common.container) gives them."""
        super().__init__("avp_prediction", **node_options)
        p = declare_and_validate(self, PREDICTION_PARAMS)
        self.method = p["method"]
        self.config = prediction_config(p)
        self.lot = None
        self.predictor = None
        self.obs: dict[int, Observation] = {}
        self.intentions: dict[int, IntentionArray] = {}
        self.answers = StepAnswers()  # the last step answered and its predictions message
        self.reject = RateLimitedLog(self.get_logger().error)  # bad inputs: one line a second per reason
        self.reject_warn = RateLimitedLog(self.get_logger().warning)
        self.auth = Authenticator(self, p["auth_inputs"])  # tagged outputs, inputs from key holders only
        self.pub = self.auth.publisher(PredictedTrajectoryArray, "predictions", STEP)
        self.auth.subscription(LotMap, "lot_map", self._on_lot, LATCHED)
        self.sub_obs = self.auth.subscription(Observation, "observation", self._on_obs, STEP_INPUT)
        self.sub_int = self.auth.subscription(IntentionArray, "intentions", self._on_intentions, STEP_INPUT)
        self.get_logger().info(f"prediction method '{self.method}'")

    def _on_lot(self, msg: LotMap) -> None:
        lot = lot_from_msg_or_log(msg, self.get_logger())
        if lot is None:
            return
        self.lot = lot
        try:
            self.predictor = make_predictor(self.method, self.lot, self.config)
        except ValueError as exc:  # e.g. learned.weights that cannot be loaded: one error, no predictions
            self.get_logger().error(f"method '{self.method}': {exc}")
            self.predictor = None
            return
        if getattr(self.predictor, "info", ""):
            self.get_logger().info(self.predictor.info)  # which weights the learned predictor runs
        self.answers.reset()
        for k in sorted(self.obs):
            self._try(k)

    def _on_obs(self, msg: Observation) -> None:
        k, episode = int(msg.step), episode_of(msg.header.frame_id)
        if self.answers.is_copy(k, self.pub.publish, episode):  # re-sent observation: the same answer again
            return
        if why := self.answers.stale(k, episode):
            self.reject_warn(f"{self.sub_obs.topic_name}: {why}")
            return
        if self.answers.begin(episode):
            self.get_logger().info(f"{self.sub_obs.topic_name}: episode {episode:x} begins at step {k}")
        for d in (self.obs, self.intentions):  # what is buffered of another episode is not answered
            for s in [s for s, m in d.items() if episode_of(m.header.frame_id) != episode]:
                del d[s]
        self.obs[k] = msg
        self._trim(self.obs)
        self._try(k)

    @staticmethod
    def _trim(d: dict, keep: int = 50) -> None:
        for s in sorted(d)[:-keep]:  # unmatched messages (no lot map yet, a partner that never comes)
            del d[s]

    def _on_intentions(self, msg: IntentionArray) -> None:
        k, episode = int(msg.step), episode_of(msg.header.frame_id)
        if episode < self.answers.episode or (episode == self.answers.episode and k <= self.answers.last_step):
            return  # already answered (re-sent with a re-sent observation), or of an earlier episode
        self.intentions[k] = msg
        self._trim(self.intentions)
        self._try(k)

    def _try(self, k: int) -> None:
        if self.predictor is None or k not in self.obs or k not in self.intentions:
            return
        e_obs, e_int = episode_of(self.obs[k].header.frame_id), episode_of(self.intentions[k].header.frame_id)
        if e_obs != e_int:  # of two episodes: the earlier one's message goes, the later one's waits for its partner
            (self.obs if e_obs < e_int else self.intentions).pop(k)
            return
        obs_msg, int_msg = self.obs.pop(k), self.intentions.pop(k)
        for d in (self.obs, self.intentions):  # forget anything older
            for s in [s for s in d if s < k]:
                del d[s]
        topic = self.sub_obs.topic_name
        try:
            obs = observation_from_msg(obs_msg)
            check_stamp(obs_msg.header.stamp, k, obs.dt)
            for what, ids in (("vacant_spot_ids", obs.vacant_spot_ids), ("occupied_spot_ids",
                                                                        obs.occupied_spot_ids)):
                bad = [int(i) for i in ids if not self.lot.has_spot(int(i))]
                if bad:
                    raise MessageError(f"{what}: unknown spot id {bad[0]}")
        except (MessageError, ValueError) as exc:
            self.reject(f"{topic} step {k}: {exc}; dropped")
            return
        topic = self.sub_int.topic_name
        try:
            if time_to_ns(int_msg.header.stamp) != time_to_ns(obs_msg.header.stamp):
                raise MessageError(f"header.stamp {time_to_ns(int_msg.header.stamp)} ns differs from the "
                                   f"observation's {time_to_ns(obs_msg.header.stamp)} ns")
            intentions = intentions_from_msg(int_msg, self.lot)
        except MessageError as exc:
            self.reject(f"{topic} step {k}: {exc}; dropped")
            return
        trajectories = self.predictor.predict(obs, intentions)
        out = predictions_to_msg(k, obs.dt, trajectories)
        out.header.frame_id = with_episode(out.header.frame_id, episode_of(obs_msg.header.frame_id))
        self.pub.publish(out)
        self.answers.store(k, out)


def main(args=None) -> int:
    return run_node(PredictionNode, "avp_prediction", args)


if __name__ == "__main__":
    sys.exit(main())

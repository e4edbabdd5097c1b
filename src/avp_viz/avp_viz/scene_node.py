"""avp_scene: the 3-D scene of the running graph for viewers (Foxglove, Lichtblick, RViz; docs/foxglove.md).

Topics (relative names in namespace /avp, except the two TF topics, which are global as REP-105 wants them):
  subscribes lot_map (latched), observation, beliefs, predictions, decision; with noisy sensing also
             sensing/detections and tracking/objects (drawn as they come on viz/detections and viz/tracks,
             :mod:`avp_viz.sensing_markers`)
  publishes  /tf_static (map -> odom, latched), /tf (odom -> base_link, map -> agent_<id>), and as
             visualization_msgs/MarkerArray (:mod:`avp_viz.scene`) viz/lot (latched, once per lot),
             viz/spots (latched, when a spot's colour changes), viz/scene (every step)

A sink: nothing in the ego's pipeline reads what it publishes, so it never changes an episode. It publishes the
transforms and the scene of step k (with the spot fill, if a colour changed) once observation, beliefs,
predictions and decision k have all arrived (in any order), or else when observation k + 1 does, with what came (a
graph without perception or planner); once per step (a re-sent observation sends nothing new), each stamped with the
step's simulated time. Until then it only keeps what came: the observation is read when its step is drawn, after
the planner answered it, so that in a component container (avp_common.container), where this node shares the
pipeline's thread, the scene never runs between an observation and its command. lot_map, observation, beliefs and
predictions are taken only when tagged with the user's key (``auth_inputs``); the decision only draws the plan,
so it is taken unchecked, from any publisher (a forged one changes the picture, never the
ego). Bad messages are dropped with one
rate-limited log line naming the topic; the node keeps running.
"""

from __future__ import annotations

import numpy as np
from rclpy.node import Node
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import MarkerArray

from avp_common.conversions import MessageError, beliefs_from_msg, lot_from_msg_or_log, observation_from_msg
from avp_common.msg_auth import Authenticator
from avp_common.node_main import run_node
from avp_common.params import ParamSpec, declare_and_validate
from avp_common.qos import DEBUG, LATCHED, QUIET_READER, QUIET_WRITER, STEP_INPUT, reader_qos
from avp_common.ratelog import RateLimitedLog
from avp_msgs.msg import DecisionTrace, LotMap, Observation, PlannerDecision, PredictedTrajectoryArray, SpotBeliefs
from avp_viz import scene
from avp_viz.palette import mark_seen

SCENE_PARAMS = [
    ParamSpec("auth_inputs", bool, "Take lot_map, observation, beliefs and predictions only when tagged with the "
              "user's key (avp_common.msg_auth); others are dropped and their publishers named.", default=True),
    ParamSpec("publish_tf", bool, "Publish /tf and /tf_static (REP-105: map -> odom -> base_link, map -> "
              "agent_<id>). Off where another node owns the transform tree.", default=True),
    ParamSpec("ego_index", int, "Among several egos (avp launch --egos K): this scene's ego. Its frames are prefixed "
              "ego<i>/ on the one /tf, and the ego, its plan and chosen spot drawn in its colour (avp_viz.scene); "
              "-1 = the one-ego graph.", min=-1, max=7, default=-1),
]
#: /tf as tf2 wants it: reliable, volatile, deep enough for a burst (/tf_static takes LATCHED: transient local, one)
TF = reader_qos(False, 100)
KEEP_STEPS = 20  # steps of inputs kept while waiting for their decision (bounded)


class SceneNode(Node):
    def __init__(self, **node_options) -> None:
        """``node_options``: rclpy Node keywords (``cli_args``, ``use_global_arguments``), as a component container
        (avp_common.container) gives them."""
        super().__init__("avp_scene", **node_options)
        p = declare_and_validate(self, SCENE_PARAMS)
        self.publish_tf = p["publish_tf"]
        i = p["ego_index"]
        self.prefix = "" if i < 0 else f"ego{i}/"
        self.ego_rgba = None if i < 0 else scene.EGO_COLOURS[i]
        self.lot = None
        self.obs: dict[int, Observation] = {}  # step -> its observation, as it came
        self.beliefs: dict[int, np.ndarray] = {}
        self.decisions: dict[int, PlannerDecision] = {}
        self.seen: np.ndarray | None = None  # spots the ego has observed this episode (unseen ones are drawn grey)
        self.preds: dict[int, PredictedTrajectoryArray] = {}
        self.published = -1  # the last step whose scene went out
        self.reject = RateLimitedLog(self.get_logger().error)
        self.auth = Authenticator(self, p["auth_inputs"])
        self.pub_scene = self.create_publisher(MarkerArray, "viz/scene", DEBUG, event_callbacks=QUIET_WRITER)
        self.pub_lot = self.create_publisher(MarkerArray, "viz/lot", LATCHED, event_callbacks=QUIET_WRITER)
        self.pub_spots = self.create_publisher(MarkerArray, "viz/spots", LATCHED, event_callbacks=QUIET_WRITER)
        self.fill: scene.SpotFill | None = None
        self.levels: np.ndarray | None = None  # the spot colour levels last published
        if self.publish_tf:
            self.pub_tf = self.create_publisher(TFMessage, "/tf", TF, event_callbacks=QUIET_WRITER)
            self.pub_tf_static = self.create_publisher(TFMessage, "/tf_static", LATCHED, event_callbacks=QUIET_WRITER)
        # noisy sensing (docs/perception.md): the raw detections and the tracks, drawn apart as they come
        from autoware_perception_msgs.msg import DetectedObjects, TrackedObjects

        from avp_viz.sensing_markers import detection_markers, track_markers

        self.pub_detections = self.create_publisher(MarkerArray, "viz/detections", DEBUG, event_callbacks=QUIET_WRITER)
        self.pub_tracks = self.create_publisher(MarkerArray, "viz/tracks", DEBUG, event_callbacks=QUIET_WRITER)
        self.auth.subscription(DetectedObjects, "sensing/detections",
                               lambda m: self.pub_detections.publish(detection_markers(m)), STEP_INPUT)
        self.auth.subscription(TrackedObjects, "tracking/objects",
                               lambda m: self.pub_tracks.publish(track_markers(m)), STEP_INPUT)
        self.auth.subscription(LotMap, "lot_map", self._on_lot, LATCHED)
        self.auth.subscription(Observation, "observation", self._on_obs, STEP_INPUT)
        self.auth.subscription(SpotBeliefs, "beliefs", self._on_beliefs, STEP_INPUT)
        self.auth.subscription(PredictedTrajectoryArray, "predictions", self._on_preds, STEP_INPUT)
        self.create_subscription(PlannerDecision, "decision", self._on_decision, STEP_INPUT,
                                 event_callbacks=QUIET_READER)
        self.traces: dict[int, DecisionTrace] = {}  # the planner's decision trace: drawn when it is there
        self.create_subscription(DecisionTrace, "avp_planner/debug/decision",
                                 lambda m: self.traces.__setitem__(int(m.step), m), STEP_INPUT,
                                 event_callbacks=QUIET_READER)

    def _on_lot(self, msg: LotMap) -> None:
        lot = lot_from_msg_or_log(msg, self.get_logger())
        if lot is None:
            return
        self.lot = lot
        self._forget()
        self.fill = scene.SpotFill(lot)
        self.pub_lot.publish(scene.lot_markers(lot, msg.header.stamp))
        if self.publish_tf:
            self.pub_tf_static.publish(scene.static_transforms(msg.header.stamp, self.prefix))

    def _on_obs(self, msg: Observation) -> None:
        k = int(msg.step)
        if k < self.published:  # a new episode
            self._forget()
        # kept as it came; read when step k is drawn, after the pipeline answered it (in a component container this
        # node shares the pipeline's thread: nothing of the scene's runs between the observation and the command)
        self.obs[k] = msg
        if k - 1 in self.obs and k - 1 > self.published:  # step k - 1 is over: draw it with what came
            self._publish(k - 1, self.decisions.get(k - 1))
        self._trim()

    def _on_beliefs(self, msg: SpotBeliefs) -> None:
        if self.lot is None:
            return
        try:
            self.beliefs[int(msg.step)] = beliefs_from_msg(msg, self.lot)
        except MessageError as exc:
            self.reject(f"beliefs step {int(msg.step)}: {exc}; dropped")
            return
        self._try(int(msg.step))

    def _on_preds(self, msg: PredictedTrajectoryArray) -> None:
        self.preds[int(msg.step)] = msg
        self._try(int(msg.step))

    def _on_decision(self, msg: PlannerDecision) -> None:
        self.decisions[int(msg.step)] = msg
        self._try(int(msg.step))

    def _try(self, k: int) -> None:
        """Step k's scene once all its messages are here (they travel on different topics: any order)."""
        if k > self.published and all(k in d for d in (self.obs, self.beliefs, self.preds, self.decisions)):
            self._publish(k, self.decisions[k])

    def _publish(self, k: int, decision: PlannerDecision | None) -> None:
        """Step k's transforms and scene (once per step: a re-sent observation sends none)."""
        msg = self.obs[k]
        self.published, stamp = k, msg.header.stamp
        try:
            obs = observation_from_msg(msg)
        except MessageError as exc:
            self.reject(f"observation step {k}: {exc}; dropped")
            return
        if self.publish_tf:
            self.pub_tf.publish(scene.transforms(obs, stamp, self.prefix))
        if self.lot is None:
            return
        if self.seen is None:
            self.seen = np.zeros(self.lot.n_spots, dtype=bool)
        mark_seen(self.seen, self.lot, obs)
        beliefs = self.beliefs.get(k)
        if beliefs is not None:
            beliefs = np.where(self.seen, beliefs, np.nan)
        levels = scene.belief_levels(beliefs, self.lot.n_spots)
        if self.levels is None or not np.array_equal(levels, self.levels):
            self.pub_spots.publish(self.fill.marker(levels, stamp))
            self.levels = levels
        self.pub_scene.publish(scene.scene_markers(self.lot, obs, self.preds.get(k), decision, stamp,
                                                   self.traces.get(k), self.ego_rgba))

    def _forget(self) -> None:
        for d in (self.obs, self.beliefs, self.preds, self.decisions, self.traces):
            d.clear()
        self.published, self.seen, self.levels = -1, None, None

    def _trim(self) -> None:
        for d in (self.obs, self.beliefs, self.preds, self.decisions, self.traces):
            for s in sorted(d)[:-KEEP_STEPS]:
                del d[s]


def main(args=None) -> int:
    return run_node(SceneNode, "avp_scene", args)


if __name__ == "__main__":
    import sys

    sys.exit(main())

"""avp_perception belief node: the thin ROS wrapper around :meth:`PerceptionCore.believe` (§V-A, §V-B).

Topics (relative; the launcher puts every node in namespace /avp):
  subscribes lot_map (latched), observation
  publishes  beliefs (avp_msgs/SpotBeliefs, b_t of every spot of the lot),
             intentions (avp_msgs/IntentionArray, §V-A), both stamped like the observation they answer;
             ego_intention (avp_msgs/IntentionArray with one Intention, vehicle_id 0 = the ego: eta_0,i of the
             ego's own BEV, §VI-B-3), only with ``ego_intent``;
             debug/bev (sensor_msgs/Image rgb8: the BEVs I_k,0 of the observed dynamic vehicles side by side),
             debug/occupancy (nav_msgs/OccupancyGrid of b_t; unknown = -1 for never-observed spots) — each
             only while subscribed, or always / never (``debug.*`` parameters).

``belief_source`` says what follows eq. (7) (Table I methods, docs/experiment.md): ``intent`` — eq. (8) with
the intent CNN of every observed dynamic vehicle (the paper); ``nawaz`` — Nawaz et al.'s occupancy on the observed
vacant spots from constant-velocity predictions that this node computes itself (``nawaz.*``; computing them here
keeps the graph acyclic: the prediction node waits for this node's intentions); ``observation`` — eq. (7) only.
With ``nawaz`` / ``observation`` the intentions topic carries an empty array each step (the prediction node's
lock-step partner).

One output per observation step, in order. An observation of a step already answered (the simulator
re-sends in lock-step when a reply went missing) gets the same messages again, not a second update. An
observation of a later episode (the episode id in its tag) starts a new episode: the belief map, the
ego trail and the intent bookkeeping are reset; one of an earlier episode, or of a step lower than the last one
answered (step 0 included), is dropped (avp_common.step_answers). Outputs carry the observation's episode id. A
malformed observation (NaN/inf, unknown spot ids, a header stamp that is not
step * dt) is dropped with one error naming the topic; the node keeps running.
"""

from __future__ import annotations

import sys
from dataclasses import replace

import numpy as np
from nav_msgs.msg import OccupancyGrid
from rclpy.node import Node
from sensor_msgs.msg import Image

from avp_common.conversions import (
    MessageError,
    beliefs_to_msg,
    check_stamp,
    lot_from_msg_or_log,
    observation_from_msg,
)
from avp_common.msg_auth import Authenticator, episode_of, with_episode
from avp_common.node_main import run_node
from avp_common.params import declare_and_validate
from avp_common.qos import DEBUG, LATCHED, QUIET_WRITER, STEP, STEP_INPUT
from avp_common.ratelog import RateLimitedLog
from avp_common.step_answers import StepAnswers
from avp_msgs.msg import IntentionArray, LotMap, Observation, SpotBeliefs
from avp_perception.conversions import intentions_to_msg
from avp_perception.core.debug_views import belief_grid, grid_layout, tile_bevs
from avp_perception.core.nawaz import NawazOccupancy
from avp_perception.core.pipeline import PerceptionCore, make_intent_predictor
from avp_perception.params import BELIEF_PARAMS, bev_config, nawaz_config

EGO_VEHICLE_ID = 0  # vehicle_id of the ego's intention on ego_intention (the ego has no id among observed vehicles)


def check_spot_ids(obs, lot) -> None:
    """MessageError naming the first vacant/occupied spot id the lot does not have."""
    for what, ids in (("vacant_spot_ids", obs.vacant_spot_ids), ("occupied_spot_ids", obs.occupied_spot_ids)):
        for sid in np.asarray(ids).tolist():
            if not lot.has_spot(sid):
                raise MessageError(f"{what}: unknown spot id {sid}")


class BeliefNode(Node):
    def __init__(self, **node_options) -> None:
        """``node_options``: rclpy Node keywords (``cli_args``, ``use_global_arguments``), as a component container
        (avp_common.container) gives them."""
        super().__init__("avp_belief", **node_options)
        p = declare_and_validate(self, BELIEF_PARAMS)
        self.p = p
        self.bev_config = bev_config(p)
        self.nawaz_config = nawaz_config(p)
        self.source, self.ego_intent = p["belief_source"], p["ego_intent"]
        import torch

        torch.set_num_threads(p["torch_threads"])
        self.intent, which = make_intent_predictor(None, self.bev_config, p["intent.weights"], p["intent.seed"],
                                                   p["intent.mode"])
        self.get_logger().info(which)
        self.lot = None
        self.core: PerceptionCore | None = None
        self.layout = None
        self.seen: np.ndarray | None = None
        self.pending: dict[int, Observation] = {}  # observations that arrived before the lot map
        self.nawaz: NawazOccupancy | None = None
        # the last answer: (beliefs msg, intentions msg, ego_intention msg or None, observation msg, core output)
        self.answers = StepAnswers()
        self.reject = RateLimitedLog(self.get_logger().error)  # bad inputs: one line a second per reason
        self.reject_warn = RateLimitedLog(self.get_logger().warning)
        self.auth = Authenticator(self, p["auth_inputs"])  # tagged outputs, inputs from key holders only
        self.pub_beliefs = self.auth.publisher(SpotBeliefs, "beliefs", STEP)
        self.pub_intentions = self.auth.publisher(IntentionArray, "intentions", STEP)
        self.pub_ego = self.auth.publisher(IntentionArray, "ego_intention", STEP) if self.ego_intent else None
        self.pub_bev = self.create_publisher(Image, "debug/bev", DEBUG, event_callbacks=QUIET_WRITER)
        self.pub_occupancy = self.create_publisher(OccupancyGrid, "debug/occupancy", DEBUG,
                                                   event_callbacks=QUIET_WRITER)
        self.auth.subscription(LotMap, "lot_map", self._on_lot, LATCHED)
        self.sub_obs = self.auth.subscription(Observation, "observation", self._on_obs, STEP_INPUT)
        self.get_logger().info(f"belief source '{self.source}'" + (", ego intention on ego_intention"
                                                                    if self.ego_intent else ""))

    # ------------------------------------------------------------------------------------------ inputs
    def _on_lot(self, msg: LotMap) -> None:
        lot = lot_from_msg_or_log(msg, self.get_logger())
        if lot is None:
            return
        self.lot = lot
        self.intent.renderer(lot)
        self.core = PerceptionCore(lot, self.bev_config, intent=self.intent, t_hist=self.p["t_hist"],
                                   belief_init=self.p["belief_init"], keep_bevs=True)
        self.nawaz = NawazOccupancy(lot, self.nawaz_config)
        self.layout = grid_layout(lot, self.p["debug.occupancy_resolution"])
        self.seen = np.zeros(lot.n_spots, dtype=bool)
        self.answers.reset()
        self.get_logger().info(f"lot '{lot.name}' ({lot.n_spots} spots)")
        for k in sorted(self.pending):
            self._on_obs(self.pending.pop(k))

    def _on_obs(self, msg: Observation) -> None:
        if self.core is None:
            self.pending[int(msg.step)] = msg
            for old in sorted(self.pending)[:-10]:
                del self.pending[old]
            return
        topic = self.sub_obs.topic_name
        step, episode = int(msg.step), episode_of(msg.header.frame_id)
        if self.answers.is_copy(step, self._republish, episode):
            return
        if why := self.answers.stale(step, episode):
            self.reject_warn(f"{topic}: {why}")
            return
        try:
            obs = observation_from_msg(msg)
            check_stamp(msg.header.stamp, step, obs.dt)
            check_spot_ids(obs, self.lot)
        except (MessageError, ValueError) as exc:
            self.reject(f"{topic} step {step}: {exc}; dropped")
            return
        if self.answers.begin(episode):
            self.get_logger().info(f"{topic}: episode {episode:x} begins at step {step}; beliefs and intent state "
                                   "reset")
            self.core.reset()
            self.seen[:] = False
        out = self.core.believe(obs, self.source, self.nawaz, self.ego_intent)
        self.seen |= self.core.beliefs.observed_mask
        beliefs = beliefs_to_msg(step, obs.dt, self.lot.spot_ids, out.beliefs)
        intentions = intentions_to_msg(step, obs.dt, out.intentions)
        ego = None
        if out.ego_intention is not None:
            ego = intentions_to_msg(step, obs.dt, [replace(out.ego_intention, vehicle_id=EGO_VEHICLE_ID)])
        for m in (beliefs, intentions, ego):
            if m is not None:  # the answer belongs to the observation's episode
                m.header.frame_id = with_episode(m.header.frame_id, episode)
        self._publish(beliefs, intentions, ego)
        self.answers.store(step, (beliefs, intentions, ego, msg, out))
        self._publish_debug(msg, out)

    def _republish(self, answer: tuple) -> None:
        """A re-sent observation of the step answered last: the same answer again."""
        beliefs, intentions, ego, obs_msg, out = answer
        self._publish(beliefs, intentions, ego)
        self._publish_debug(obs_msg, out)

    def _publish(self, beliefs: SpotBeliefs, intentions: IntentionArray, ego: IntentionArray | None) -> None:
        if ego is not None:  # first: the planner's last input in lock-step is the prediction node's answer
            self.pub_ego.publish(ego)
        self.pub_beliefs.publish(beliefs)
        self.pub_intentions.publish(intentions)

    # ------------------------------------------------------------------------------------------ debug
    def _publish_debug(self, obs_msg: Observation, out) -> None:
        if self._wanted(self.p["debug.bev"], self.pub_bev):
            self.pub_bev.publish(self._bev_msg(obs_msg, out.bevs))
        if self._wanted(self.p["debug.occupancy"], self.pub_occupancy):
            self.pub_occupancy.publish(self._occupancy_msg(obs_msg, out.beliefs))

    @staticmethod
    def _wanted(mode: str, pub) -> bool:
        return mode == "always" or (mode == "subscribed" and pub.get_subscription_count() > 0)

    def _bev_msg(self, obs_msg: Observation, bevs) -> Image:
        img = tile_bevs([b.image for b in bevs], self.bev_config.size_px)
        msg = Image()
        msg.header.stamp = obs_msg.header.stamp
        msg.header.frame_id = "bev"
        msg.height, msg.width = int(img.shape[0]), int(img.shape[1])
        msg.encoding = "rgb8"
        msg.is_bigendian = 0
        msg.step = 3 * msg.width
        msg.data = img.tobytes()
        return msg

    def _occupancy_msg(self, obs_msg: Observation, beliefs: np.ndarray) -> OccupancyGrid:
        lay = self.layout
        msg = OccupancyGrid()
        msg.header.stamp = obs_msg.header.stamp
        msg.header.frame_id = "map"
        msg.info.map_load_time = obs_msg.header.stamp
        msg.info.resolution = float(lay.resolution)
        msg.info.width, msg.info.height = lay.width, lay.height
        msg.info.origin.position.x, msg.info.origin.position.y = lay.origin
        msg.info.origin.orientation.w = 1.0
        msg.data = belief_grid(lay, beliefs, self.seen).ravel()
        return msg


def main(args=None) -> int:
    return run_node(BeliefNode, "avp_belief", args)


if __name__ == "__main__":
    sys.exit(main())

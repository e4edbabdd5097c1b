"""avp_tracker node: the thin ROS wrapper around :class:`avp_tracking.core.tracker.Tracker` (docs/perception.md,
"Tracking").

Topics (relative; the launcher puts it in namespace /avp):
  subscribes lot_map (latched); sensing/observation (avp_msgs/Observation without vehicles or pedestrians: the
             ego's localisation estimate, the spots read, the rays; the simulator's noisy sensing);
             sensing/detections (autoware_perception_msgs/DetectedObjects: the detector's objects, no ids)
  publishes  observation (avp_msgs/Observation: the frame with the confirmed tracks as its vehicles and
             pedestrians, ids and pose histories the tracker's; what the belief and prediction nodes and the planner
             read), tracking/objects (autoware_perception_msgs/TrackedObjects of the same tracks)

``sync: stamp`` (lock-step, the simulator's detections): frame k is answered once the detections stamped t_k are
in, or after ``detection_wait`` wall seconds without them (the tracks coasted; a warning). ``sync: latest`` (a real
detector on its own clock): each frame takes the newest detections received within ``max_detection_age`` wall
seconds. A user with a real detector remaps ``sensing/detections`` to its output and, unless it signs with the
stack's key, sets ``auth_detections: false`` (docs/perception.md, "A real detector").

The step rules of the other nodes apply (avp_common.step_answers): a re-sent frame gets the same answer again, a
later episode resets the tracks, an earlier one is dropped. A bad detection message (NaN or infinite values, a size
that is not positive, too many objects, another frame) is refused whole with one error naming the topic and field;
the node keeps running and the step goes on without it.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from rclpy.node import Node
from std_msgs.msg import Header

from avp_common.conversions import (
    MessageError,
    check_stamp,
    lot_from_msg_or_log,
    observation_from_msg,
    observation_to_msg,
    time_to_ns,
)
from avp_common.detection_msgs import DetectionError, detections_from_msg, tracks_to_msg
from avp_common.msg_auth import Authenticator, episode_of, with_episode
from avp_common.node_main import run_node
from avp_common.params import declare_and_validate
from avp_common.qos import LATCHED, STEP, STEP_INPUT
from avp_common.ratelog import RateLimitedLog
from avp_common.step_answers import StepAnswers
from avp_msgs.msg import LotMap, Observation
from avp_tracking.core.perceive import TrackingPerception
from avp_tracking.core.tracker import Tracker
from avp_tracking.params import TRACKER_NODE_PARAMS, tracker_config
from avp_world.detections import SensedFrame

#: wall seconds between the observation subscribers being matched and the first answer (as the simulator's step 0)
SETTLE_S = 0.5


class TrackerNode(Node):
    def __init__(self, **node_options) -> None:
        super().__init__("avp_tracker", **node_options)
        self.p = declare_and_validate(self, TRACKER_NODE_PARAMS)
        self.reject = RateLimitedLog(self.get_logger().error)
        self.warn = RateLimitedLog(self.get_logger().warning)
        self.auth = Authenticator(self, self.p["auth_inputs"])
        self.det_auth = Authenticator(self, self.p["auth_detections"])
        self.pub_obs = self.auth.publisher(Observation, "observation", STEP)
        from autoware_perception_msgs.msg import DetectedObjects, TrackedObjects

        self.pub_tracks = self.auth.publisher(TrackedObjects, "tracking/objects", STEP)
        self.auth.subscription(LotMap, "lot_map", self._on_lot, LATCHED)
        self.sub_frame = self.auth.subscription(Observation, "sensing/observation", self._on_frame, STEP_INPUT)
        self.sub_det = self.det_auth.subscription(DetectedObjects, "sensing/detections", self._on_detections,
                                                  STEP_INPUT)
        self.perception: TrackingPerception | None = None
        self.answers = StepAnswers()
        self.detections: dict[int, tuple[list, list]] = {}  # stamp (ns) -> (vehicles, pedestrians); sync stamp
        self.latest: tuple[float, tuple[list, list]] | None = None  # (wall time, detections); sync latest
        self.waiting: tuple[float, Observation] | None = None  # a frame whose detections are not in yet
        self.held: tuple | None = None  # an answer held until observation's subscribers are there
        self.matched_since: float | None = None
        self.create_timer(0.05, self._tick)
        self.get_logger().info(f"avp_tracker up: sync {self.p['sync']}, detections on {self.sub_det.topic_name}")

    # ------------------------------------------------------------------------------------------ inputs
    def _on_lot(self, msg: LotMap) -> None:
        lot = lot_from_msg_or_log(msg, self.get_logger())
        if lot is None:
            return
        self.perception = TrackingPerception(lot, Tracker(tracker_config(self.p, 0.1, self.p["t_hist"])))
        self.answers.reset()
        self.get_logger().info(f"lot '{lot.name}' ({lot.n_spots} spots)")

    def _on_detections(self, msg) -> None:
        try:
            dets = detections_from_msg(msg, self.p["max_objects"])
        except DetectionError as exc:
            self.reject(f"{self.sub_det.topic_name}: {exc}; the message is dropped")
            return
        if self.p["sync"] == "latest":
            self.latest = (time.monotonic(), dets)
            return
        stamp = time_to_ns(msg.header.stamp)
        self.detections[stamp] = dets
        for old in sorted(self.detections)[:-20]:
            del self.detections[old]
        if self.waiting is not None and time_to_ns(self.waiting[1].header.stamp) == stamp:
            _, frame = self.waiting
            self.waiting = None
            self._answer(frame, dets)

    def _on_frame(self, msg: Observation) -> None:
        if self.perception is None:
            self.warn(f"{self.sub_frame.topic_name}: no lot map yet; step {msg.step} dropped")
            return
        step, episode = int(msg.step), episode_of(msg.header.frame_id)
        if self.answers.is_copy(step, self._publish, episode):
            return
        if why := self.answers.stale(step, episode):
            self.warn(f"{self.sub_frame.topic_name}: {why}")
            return
        if self.p["sync"] == "latest":
            fresh = self.latest is not None and time.monotonic() - self.latest[0] <= self.p["max_detection_age"]
            self._answer(msg, self.latest[1] if fresh else ([], []))
            return
        dets = self.detections.pop(time_to_ns(msg.header.stamp), None)
        if dets is None:
            self.waiting = (time.monotonic(), msg)
            return
        self._answer(msg, dets)

    def _tick(self) -> None:
        if self.waiting is not None and time.monotonic() - self.waiting[0] > self.p["detection_wait"]:
            _, frame = self.waiting
            self.waiting = None
            self.warn(f"{self.sub_det.topic_name}: no detections stamped like step {frame.step} within "
                      f"{self.p['detection_wait']} s; the step is answered without them (tracks coasted)")
            self._answer(frame, ([], []))
        if self.held is not None and self._subscribers_ready():
            held, self.held = self.held, None
            self._publish(held)

    def _subscribers_ready(self) -> bool:
        if self.pub_obs.get_subscription_count() < self.p["min_subscribers"]:
            self.matched_since = None
            return False
        if self.matched_since is None:
            self.matched_since = time.monotonic()
        return time.monotonic() - self.matched_since >= SETTLE_S or self.answers.last_step > 0

    # ------------------------------------------------------------------------------------------ the step
    def _answer(self, msg: Observation, dets: tuple[list, list]) -> None:
        topic = self.sub_frame.topic_name
        step, episode = int(msg.step), episode_of(msg.header.frame_id)
        try:
            base = observation_from_msg(msg)
            check_stamp(msg.header.stamp, step, base.dt)
        except (MessageError, ValueError) as exc:
            self.reject(f"{topic} step {step}: {exc}; dropped")
            return
        if self.answers.begin(episode):
            self.get_logger().info(f"{topic}: episode {episode:x} begins at step {step}; tracks reset")
            self.perception.tracker.reset()
        vehicles, peds = dets
        frame = SensedFrame(step=step, dt=base.dt, ego_pose=base.ego_pose,
                            ego_covariance=base.ego_covariance if base.ego_covariance is not None else np.zeros((3, 3)),
                            ego_length=base.ego_length, ego_width=base.ego_width, ego_speed=base.ego_speed,
                            vacant_spot_ids=base.vacant_spot_ids, occupied_spot_ids=base.occupied_spot_ids,
                            vehicles=tuple(vehicles), pedestrians=tuple(peds), ray_angle_min=base.ray_angle_min,
                            ray_angle_increment=base.ray_angle_increment, ray_ranges=base.ray_ranges)
        self.perception.tracker.cfg = _with_history(self.perception.tracker.cfg, base.dt, self.p["t_hist"])
        obs = self.perception.observe(frame)
        out = observation_to_msg(obs, with_episode("map", episode))
        tracks = tracks_to_msg(self.perception.tracker.tracks_given, Header(stamp=msg.header.stamp,
                                                                            frame_id=with_episode("map", episode)),
                               episode)
        answer = (out, tracks)
        self.answers.store(step, answer)
        if self._subscribers_ready():
            self._publish(answer)
        else:
            self.held = answer

    def _publish(self, answer: tuple) -> None:
        out, tracks = answer
        self.pub_tracks.publish(tracks)
        self.pub_obs.publish(out)


def _with_history(cfg, dt: float, t_hist: float):
    """``cfg`` with the history length of the frames' dt (t_hist / dt + 1 poses)."""
    from dataclasses import replace

    n = int(round(t_hist / dt)) + 1 if dt > 0 else cfg.history_steps
    return cfg if cfg.history_steps == n else replace(cfg, history_steps=n)


def main(args=None) -> int:
    return run_node(TrackerNode, "avp_tracker", args)


if __name__ == "__main__":
    sys.exit(main())

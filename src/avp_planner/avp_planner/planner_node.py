"""avp_planner node: the thin ROS wrapper around :class:`avp_planner.core.decision.EgoPlanner` (§V-D).

Subscribes lot_map (latched), observation, and — when enabled — beliefs, predictions and ego_intention (the
belief node's ``ego_intent``: the ego's own intention eta_0,i; the candidate spots are then tried in decreasing
eta_0,i, Table I "Implicit", §VI-B-3) and v2v/beacons (an ego of a fleet: what the egos before it announced,
avp_planner.v2v_node; ``use_beacons``); in lock-step it decides once all enabled inputs stamped like observation k
have arrived. Publishes cmd
(TwistStamped, stamped like the observation it answers), plan (nav_msgs/Path), decision
(avp_msgs/PlannerDecision with timings). Never reads ground truth.

A lifecycle (managed) node, so that planners can be swapped while the simulator runs (`avp swap-planner`,
docs/custom_planner.md): *configure* builds the planner core for the lot, *activate* starts answering
observations (the newest one buffered while inactive first), *deactivate* stops it (no command is
published while inactive: the simulator holds the ego still), *shutdown* ends the process (in a component
container, avp_common.container: unloads the node, :attr:`PlannerNode.end_hook`). With
``autostart`` (default) it configures and activates itself at start-up. An observation of a later episode
(the episode id in its tag) starts a new episode (the core is reset); one of an earlier episode, or of a
step older than the newest seen (step 0 included), is dropped with a warning; commands carry the episode id.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import replace

import rclpy
from geometry_msgs.msg import TwistStamped
from nav_msgs.msg import Path
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from visualization_msgs.msg import MarkerArray

from avp_common.conversions import (
    MessageError,
    beacons_from_msg,
    beliefs_from_msg,
    lot_from_msg_or_log,
    observation_from_msg,
    predictions_from_msg,
)
from avp_common.lifecycle import guard_lifecycle_services
from avp_common.msg_auth import Authenticator, episode_of, with_episode
from avp_common.node_main import run_node
from avp_common.params import (
    dataclass_from_values,
    declare_and_validate,
)
from avp_common.qos import LATCHED, QUIET_READER, QUIET_WRITER, RESEND_ANSWER_INTERVAL, STATUS, STEP, STEP_INPUT
from avp_common.ratelog import RateLimitedLog
from avp_motion.settings import DEFAULT_SETTINGS
from avp_motion.trace import DecisionTrace as DecisionTrace_
from avp_msgs.msg import (
    DecisionTrace,
    EgoBeaconArray,
    EpisodeStatus,
    IntentionArray,
    LotMap,
    Observation,
    PlannerDecision,
    PredictedTrajectoryArray,
    SpotBeliefs,
)
from avp_planner.core.spot_selection import spot_selector_class
from avp_planner.decision_msg import decision_msg, ego_priority_from_msg, plan_markers, plan_msg
from avp_planner.params import PLANNER_PARAMS
from avp_planner.trace_msg import trace_to_msg

MIN_REALTIME_BUDGET = 0.01  # s of searching a real-time decision always gets (realtime_decision_deadline)
MAX_PENDING = 100  # observations kept while their other inputs are awaited (10 s of steps)


class PlannerNode(LifecycleNode):
    #: what *shutdown* ends: the process (rclpy.try_shutdown); a component container (avp_common.container) sets
    #: its own, which unloads this node and keeps the others of the process running
    end_hook: Callable[[], object] = staticmethod(rclpy.try_shutdown)

    def __init__(self, **node_options) -> None:
        """``node_options``: rclpy Node keywords (``cli_args``, ``use_global_arguments``), as a component container
        (avp_common.container) gives them."""
        super().__init__("avp_planner", **node_options)
        guard_lifecycle_services(self)
        p = declare_and_validate(self, PLANNER_PARAMS)
        self.use_beliefs, self.use_predictions = p["use_beliefs"], p["use_predictions"]
        self.use_ego_intention, self.use_beacons = p["use_ego_intention"], p["use_beacons"]
        self.stale_timeout = p["stale_input_timeout"]
        self.p_deadline = p["realtime_decision_deadline"]
        self.realtime = False  # from the simulator's latched episode_status (lock_step)
        self.obs_wall: dict[int, float] = {}  # wall time each pending observation arrived
        self.obs_sent: dict[int, int] = {}  # its DDS source timestamp [ns, system clock]
        self.stale_since: float | None = None  # start of the current stall (one log line each way)
        self.held_steps = 0
        self.zeroed: set[int] = set()  # steps answered with v = ω = 0 during the stall
        # the last decided step and its command: an observation of that step again (a lock-step re-send, or a copy
        # replayed by another process) gets the same command again, at most once a second, and never a second
        # decision (which would advance the planner's state: the episode would differ from the in-process run)
        self.answered: tuple[int, float, float] | None = None
        self.answered_at = -float("inf")
        self.settings = dataclass_from_values(DEFAULT_SETTINGS, p).validate()
        try:
            spot_selector_class(self.settings.decision.spot_selector)
        except ValueError as exc:
            raise ValueError(f"parameter decision.spot_selector: {exc}") from None
        if self.settings.collision.reactive_evidence == "told":  # nothing on the graph names the reacting agents
            raise ValueError("parameter collision.reactive_evidence: 'told' is for an in-process caller that names "
                             "the agents that react (EgoPlanner.tell_reacting: the oracle bound); the node has no "
                             "such source, use lot, agent or assumed")
        self.planner = None
        self.lot = None
        self.configured = False
        self.active = False
        self.episode = -1  # the running episode's id (avp_common.msg_auth.episode_of)
        self.last_step: int | None = None  # newest observation step seen
        self.obs: dict[int, Observation] = {}
        self.beliefs: dict[int, SpotBeliefs] = {}
        self.preds: dict[int, PredictedTrajectoryArray] = {}
        self.ego_int: dict[int, IntentionArray] = {}
        self.heard: dict[int, EgoBeaconArray] = {}  # what the egos before this one announced (avp_v2v)
        self.inputs = (self.obs, self.beliefs, self.preds, self.ego_int, self.heard)
        self.reject = RateLimitedLog(self.get_logger().error)  # bad inputs: one line a second per reason
        self.reject_warn = RateLimitedLog(self.get_logger().warning)
        self.skip_log = RateLimitedLog(self.get_logger().info, period=5.0)  # real time: steps skipped when behind
        self.skipped = 0
        self.auth = Authenticator(self, p["auth_inputs"])  # inputs from holders of the key only, cmd tagged
        self.pub_cmd = self.auth.publisher(TwistStamped, "cmd", STEP)
        self.pub_plan = self.create_publisher(Path, "plan", STEP, event_callbacks=QUIET_WRITER)
        # tagged: the spot-reservation book of several egos reads it (avp_planner.reservation_node)
        self.pub_decision = self.auth.publisher(PlannerDecision, "decision", STEP)
        # why the ego does what it does, every step (the decision trace): mode, idle cause, blocking agent
        self.pub_trace = self.create_publisher(DecisionTrace, "~/debug/decision", STEP, event_callbacks=QUIET_WRITER)
        self.trace = DecisionTrace_(0.1)
        self.pub_markers = self.create_publisher(MarkerArray, "debug/markers", STEP, event_callbacks=QUIET_WRITER)
        self.auth.subscription(LotMap, "lot_map", self._on_lot, LATCHED)
        self.sub_obs = self.auth.subscription(Observation, "observation", self._on_obs, STEP_INPUT, with_info=True)
        if self.use_beliefs:
            self.auth.subscription(SpotBeliefs, "beliefs", self._on_beliefs, STEP_INPUT)
        if self.use_predictions:
            self.auth.subscription(PredictedTrajectoryArray, "predictions", self._on_preds, STEP_INPUT)
        if self.use_ego_intention:
            self.auth.subscription(IntentionArray, "ego_intention", self._on_ego_intention, STEP_INPUT)
        if self.use_beacons:  # a fleet's V2V channel (decision.ego_yield)
            self.auth.subscription(EgoBeaconArray, "v2v/beacons", lambda m: self._on_input(self.heard, m), STEP_INPUT)
        self.create_subscription(EpisodeStatus, "episode_status", self._on_status, STATUS, event_callbacks=QUIET_READER)
        self.create_timer(0.05, self._check_stale)
        if p["autostart"]:
            self.trigger_configure()
            self.trigger_activate()

    # ---------------------------------------------------------------- lifecycle
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.configured = True
        self._build()
        self.get_logger().info(f"configured ({'lot known' if self.planner else 'waiting for lot_map'})")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = True
        self.get_logger().info("activated: answering observations")
        for k in sorted(self.obs):  # the newest observation buffered while inactive
            self._try(k)
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        self.get_logger().info("deactivated: no commands until activated again")
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.configured, self.planner = False, None
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        self.get_logger().info("shut down: exiting")
        self._exit_timer = self.create_timer(0.2, lambda: self.end_hook())  # after the service reply
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        return TransitionCallbackReturn.SUCCESS

    def _build(self) -> None:
        from avp_planner.core.decision import EgoPlanner

        if self.configured and self.lot is not None and self.planner is None:
            self.planner = EgoPlanner(self.lot, self.settings)

    # ---------------------------------------------------------------- inputs
    def _on_lot(self, msg: LotMap) -> None:
        lot = lot_from_msg_or_log(msg, self.get_logger())
        if lot is None:
            return
        self.lot = lot
        self.planner = None
        self._build()
        for k in sorted(self.obs):
            self._try(k)

    def _on_obs(self, msg: Observation, info=None) -> None:
        k, episode = int(msg.step), episode_of(msg.header.frame_id)
        if episode < self.episode:  # a replayed recording of an earlier episode
            self.reject_warn(f"{self.sub_obs.topic_name}: step {k} of an episode that ended (a replay of an earlier "
                             "episode); dropped")
            return
        if episode > self.episode:  # a new episode (reset): forget the old one (its step 0 again is a copy)
            if self.episode >= 0 and self.planner is not None:
                self.planner.reset()
            self.trace = DecisionTrace_(0.1)
            self.episode, self.last_step, self.answered = episode, None, None
            for d in self.inputs:
                for old in [s for s, m in d.items() if episode_of(m.header.frame_id) != episode]:
                    del d[old]
        elif self.last_step is not None and k < self.last_step:
            self.reject_warn(
                f"{self.sub_obs.topic_name}: step {k} is older than step {self.last_step} (out of order); dropped")
            return
        if k in self.obs:
            return  # re-sent observation still pending
        if self.answered is not None and self.answered[0] == k:
            if time.monotonic() - self.answered_at >= RESEND_ANSWER_INTERVAL:
                self._publish_cmd(msg.header.stamp, self.answered[1], self.answered[2])
                self.answered_at = time.monotonic()
            return
        self.last_step = k
        self.obs[k] = msg
        self.obs_wall[k] = time.monotonic()
        self.obs_sent[k] = int(info["source_timestamp"]) if info else 0
        for old in sorted(self.obs)[:-MAX_PENDING]:  # bounded: a hung input node must not grow the queue
            del self.obs[old]
        for old in [s for s in self.obs_wall if s not in self.obs]:
            del self.obs_wall[old]
            self.obs_sent.pop(old, None)
        if not self.active:  # keep only the newest inputs while inactive
            for d in self.inputs:
                for old in [s for s in d if s < k]:
                    del d[old]
        self._try(k)

    def _on_beliefs(self, msg: SpotBeliefs) -> None:
        self._on_input(self.beliefs, msg)

    def _on_preds(self, msg: PredictedTrajectoryArray) -> None:
        self._on_input(self.preds, msg)

    def _on_ego_intention(self, msg: IntentionArray) -> None:
        self._on_input(self.ego_int, msg)

    def _on_input(self, inputs: dict, msg) -> None:
        """Keep step k's beliefs / predictions / ego intention (not one of an earlier episode: a replay)."""
        if episode_of(msg.header.frame_id) < self.episode:
            return
        inputs[int(msg.step)] = msg
        self._try(int(msg.step))

    def _try(self, k: int) -> None:
        if not self.active or self.planner is None or k not in self.obs:
            return
        if ((self.use_beliefs and k not in self.beliefs) or (self.use_predictions and k not in self.preds)
                or (self.use_ego_intention and k not in self.ego_int) or (self.use_beacons and k not in self.heard)):
            return
        episode = episode_of(self.obs[k].header.frame_id)
        for d in self.inputs[1:]:  # an input of another episode for this step: the earlier one goes
            if k in d and episode_of(d[k].header.frame_id) != episode:
                (d if episode_of(d[k].header.frame_id) < episode else self.obs).pop(k)
                return
        if self.realtime and k < max(self.obs):
            # real time: a newer observation is already waiting, so deciding this one would only answer a step the
            # simulator has left (its command would be ignored) and put the next answer further behind; skip it
            for d in (self.obs, *self.inputs[1:]):
                d.pop(k, None)
            self.skipped += 1
            self.skip_log(f"{self.sub_obs.topic_name}: step {k} skipped, a newer observation is waiting (real time, "
                          f"the planner is behind); {self.skipped} skipped so far")
            return
        msg = self.obs.pop(k)
        if self.stale_since is not None:
            self.get_logger().info(f"inputs fresh again at step {k} after {time.monotonic() - self.stale_since:.1f} s "
                                   f"({self.held_steps} steps held still)")
            self.stale_since, self.held_steps = None, 0
            self.zeroed.clear()
        topic = self.sub_obs.topic_name
        try:
            obs = observation_from_msg(msg)
            topic = self.sub_obs.topic_name.replace("observation", "beliefs")
            beliefs = beliefs_from_msg(self.beliefs.pop(k), self.lot) if self.use_beliefs else None
            topic = self.sub_obs.topic_name.replace("observation", "predictions")
            preds = predictions_from_msg(self.preds.pop(k)) if self.use_predictions else []
            topic = self.sub_obs.topic_name.replace("observation", "ego_intention")
            priority = ego_priority_from_msg(self.ego_int.pop(k), self.lot) if self.use_ego_intention else None
            topic = self.sub_obs.topic_name.replace("observation", "v2v/beacons")
            if self.use_beacons:
                obs = replace(obs, beacons=beacons_from_msg(self.heard.pop(k)))
        except MessageError as exc:
            self.reject(f"{topic} step {k}: {exc}; holding still")
            self._publish_cmd(msg.header.stamp, 0.0, 0.0)
            return
        for d in self.inputs:  # forget anything older
            for old in [s for s in d if s < k]:
                del d[old]
        budget = None
        if self.realtime and self.p_deadline > 0:
            budget = max(self.p_deadline - self._since_sent(k), MIN_REALTIME_BUDGET)
        t0 = time.perf_counter()
        decision = self.planner.decide(obs, beliefs, preds, priority, time_budget=budget)
        total = time.perf_counter() - t0
        v, om = decision.command
        if decision.reason.startswith("invalid input"):
            self.get_logger().error(f"{self.sub_obs.topic_name} step {k}: {decision.reason}; holding still")
        self._publish_cmd(msg.header.stamp, float(v), float(om))
        self.answered, self.answered_at = (k, float(v), float(om)), time.monotonic()
        self._publish_decision(msg, decision, total)

    def _since_sent(self, k: int) -> float:
        """Wall seconds since observation k was sent (its DDS source timestamp), at least since it arrived here
        (the arrival only where the clocks disagree, or by more than a second)."""
        local = time.monotonic() - self.obs_wall.get(k, time.monotonic())
        if self.obs_sent.get(k):
            since = (time.time_ns() - self.obs_sent[k]) * 1e-9
            if 0.0 <= since <= 1.0:
                return max(local, since)
        return local

    def _on_status(self, msg: EpisodeStatus) -> None:
        self.realtime = not bool(msg.lock_step)

    def _check_stale(self) -> None:
        """Real time: once the oldest pending observation has waited ``stale_input_timeout`` for its other inputs,
        answer the newest observation with v = ω = 0 (each once; a real decision for it may still follow and
        replaces it at the simulator) until a step is decided again (see the parameter)."""
        if not (self.realtime and self.active and self.stale_timeout > 0 and self.obs):
            return
        now = time.monotonic()
        oldest = min(self.obs)
        if self.stale_since is None and now - self.obs_wall.get(oldest, now) < self.stale_timeout:
            return
        k = max(self.obs)
        if self.stale_since is None:
            missing = [name for name, use, d in (("beliefs", self.use_beliefs, self.beliefs),
                                                 ("predictions", self.use_predictions, self.preds),
                                                 ("ego_intention", self.use_ego_intention, self.ego_int),
                                                 ("v2v/beacons", self.use_beacons, self.heard))
                       if use and oldest not in d]
            self.stale_since = now
            self.get_logger().error(f"stale inputs: no {', '.join(missing) or 'input'} for step {oldest} within "
                                    f"{self.stale_timeout} s (stale_input_timeout); holding still until they come")
        if k in self.zeroed:
            return
        self.zeroed.add(k)
        self.held_steps += 1
        self._publish_cmd(self.obs[k].header.stamp, 0.0, 0.0)

    def _publish_cmd(self, stamp, v: float, om: float) -> None:
        cmd = TwistStamped()
        cmd.header.stamp = stamp
        cmd.header.frame_id = with_episode("ego", self.episode)  # the simulator takes commands of its episode only
        cmd.twist.linear.x, cmd.twist.angular.z = v, om
        self.pub_cmd.publish(cmd)  # tagged (avp_common.msg_auth)

    def _publish_decision(self, obs_msg: Observation, d, total: float) -> None:
        path = plan_msg(obs_msg.header.stamp, getattr(d, "poses", None))
        self.pub_plan.publish(path)
        msg = decision_msg(d, path, int(obs_msg.step), self.episode, total)
        self.pub_decision.publish(msg)  # tagged (avp_common.msg_auth)
        self.pub_trace.publish(trace_to_msg(path.header, int(obs_msg.step), d,
                                            self.trace.add(int(obs_msg.step), d)))
        self.pub_markers.publish(plan_markers(path, msg))


def main(args=None) -> int:
    return run_node(PlannerNode, "avp_planner", args)


if __name__ == "__main__":
    sys.exit(main())

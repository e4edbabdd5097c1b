"""avp_sim node: the thin ROS wrapper around :class:`avp_sim.core.world.World`.

Topics (relative; the launcher puts every node in namespace /avp):
  publishes  lot_map (LATCHED), observation, episode_status (latched), debug/ground_truth,
             debug/braking_for (several egos only), debug/markers, debug/scan, /clock
  subscribes cmd (geometry_msgs/TwistStamped, header.stamp = stamp of the observation it answers)
  service    reset_episode (avp_msgs/srv/ResetEpisode)

Lock-step: observation k is published, the command stamped t_k is awaited, then the world steps,
so results do not depend on compute speed. Real-time: until the ego's first command (``realtime_wait_first_command``)
step 0 — observation and ground truth — is re-sent every dt; then a wall timer steps every dt with the latest
command if it answers the current observation (stamp; or one at most ``command_max_lag`` steps older)
and arrived less than ``command_watchdog`` wall seconds ago; else the ego holds still (v = ω = 0) — so
when a pipeline node dies the ego stops within one step.

K egos (``egos.count``; :mod:`avp_sim.ego_channels`): ego i's observation, cmd and episode_status are
``ego<i>/...``. Lock-step publishes every driving ego's observation k and steps once each of them has answered
it; after ``lockstep_timeout`` it names the egos that have not and re-sends their observations. Real time applies
each ego's latest command under its own watchdog.
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np
from geometry_msgs.msg import Pose2D, TwistStamped
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

from avp_common.conversions import lot_to_msg, observation_to_msg, step_to_ns, step_to_time, time_to_ns
from avp_common.detection_msgs import detections_to_msg
from avp_common.msg_auth import Authenticator, episode_of, with_episode
from avp_common.node_main import run_node
from avp_common.params import declare_and_validate
from avp_common.qos import DEBUG, GROUND_TRUTH, LATCHED, QUIET_WRITER, STATUS, STEP
from avp_common.ratelog import RateLimitedLog
from avp_msgs.msg import AgentState, BrakingFor, EpisodeStatus, GroundTruth
from avp_msgs.srv import ResetEpisode
from avp_sensing.noisy import NoisySensor, sensing_config
from avp_sim.core.factory import load_lot_param, make_world, world_config
from avp_sim.core.scenario_source import requested_scenario, served_dirs
from avp_sim.core.world import COLLISION, RUNNING, SUCCESS, TIMEOUT, World
from avp_sim.ego_channels import DriverTypeCheck, EgoChannel, make_channels, make_drivers
from avp_sim.markers import world_markers
from avp_sim.params import SIM_PARAMS
from avp_world.types import Observation

_STATE = {RUNNING: EpisodeStatus.STATE_RUNNING, SUCCESS: EpisodeStatus.STATE_SUCCESS,
          COLLISION: EpisodeStatus.STATE_COLLISION, TIMEOUT: EpisodeStatus.STATE_TIMEOUT}


#: Lock-step: wall seconds between the moment the subscribers step 0 waits for are all matched by our writers and
#: step 0 — their readers' side of the match can lag, and a volatile reader misses what was written before it
#: matched (a test saw one of two ground-truth subscribers miss step 0). Only the first episode waits (the
#: readers stay matched).
SUBSCRIBER_SETTLE_S = 0.5


def braking_for_msg(w: World, stamp) -> BrakingFor:
    """Step k's (agent, ego) pairs of :attr:`World.braking_for`, in its row-major order (the in-process fleet's)."""
    rows, egos = np.nonzero(w.braking_for)
    return BrakingFor(header=Header(stamp=stamp, frame_id="map"), step=int(w.step_index),
                      agent_ids=[int(w.vehicle_ids[r]) for r in rows], ego_indices=[int(j) for j in egos])


class SimNode(Node):
    def __init__(self) -> None:
        super().__init__("avp_sim")
        self.p = declare_and_validate(self, SIM_PARAMS)
        self.lot = load_lot_param(self.p["lot_file"])
        world_config(self.p, self.lot)  # validates the sensor block and the driven cars' poses at start-up
        self.scenario_dirs = served_dirs(self.p["scenario_dir"])  # what reset_episode may read (scenario_source)

        self.dt = self.p["dt"]
        self.lockstep = self.p["mode"] == "lockstep"
        # lot_map and observation are tagged, only tagged commands steer the ego (avp_common.msg_auth)
        self.reject = RateLimitedLog(self.get_logger().error)  # bad commands: one line a second per reason
        self.reject_warn = RateLimitedLog(self.get_logger().warning)
        self.auth = Authenticator(self, self.p["auth_inputs"])
        self.pub_lot = self.auth.publisher(type(lot_to_msg(self.lot)), "lot_map", LATCHED)
        # noisy sensing (sensing.model not exact; docs/perception.md): the observation goes to the tracker as a frame
        # without vehicles (sensing/observation) and the detections beside it (sensing/detections)
        self.sensing = sensing_config(self.p)
        if not self.sensing.exact and self.p["egos.count"] > 1:
            raise ValueError(f"parameter 'sensing.model': {self.sensing.model} sensing drives one ego (egos.count 1)")
        self.egos = make_channels(self, self.auth, self.p["egos.count"], self._on_cmd,
                                  "observation" if self.sensing.exact else "sensing/observation")
        self.pub_detections = None
        if not self.sensing.exact:
            from autoware_perception_msgs.msg import DetectedObjects

            self.pub_detections = self.auth.publisher(DetectedObjects, "sensing/detections", STEP)
        self.sensor = None  # the episode's NoisySensor (noisy sensing)
        self.sensed: tuple[int, object] | None = None  # (step, frame): a lock-step re-send repeats the frame
        if self.p["drivers.count"] and self.lockstep:
            raise ValueError(f"parameter 'drivers.count': {self.p['drivers.count']} driven cars need mode realtime "
                             "(lock-step never waits for a person)")
        self.drivers = make_drivers(self, self.p["drivers.count"], len(self.egos), self.p["drivers.stamped"],
                                    self._on_driver)
        self.driver_types = DriverTypeCheck(self, self.drivers, self.p["drivers.stamped"]) if self.drivers else None
        self.pub_status = self.create_publisher(EpisodeStatus, "episode_status", STATUS, event_callbacks=QUIET_WRITER)
        self.pub_gt = self.create_publisher(GroundTruth, "debug/ground_truth", GROUND_TRUTH,
                                            event_callbacks=QUIET_WRITER)
        # several egos: which ego each braking agent brakes for (the gridlock metric; ground truth names ego 0 only)
        self.pub_braking_for = (self.create_publisher(BrakingFor, "debug/braking_for", GROUND_TRUTH,
                                                      event_callbacks=QUIET_WRITER)
                                if self.p["egos.count"] > 1 else None)
        self.pub_markers = self.create_publisher(MarkerArray, "debug/markers", DEBUG, event_callbacks=QUIET_WRITER)
        self.pub_scan = self.create_publisher(LaserScan, "debug/scan", DEBUG, event_callbacks=QUIET_WRITER)
        self.pub_clock = self.create_publisher(Clock, "/clock", 10, event_callbacks=QUIET_WRITER)
        self.srv = self.create_service(ResetEpisode, "reset_episode", self._on_reset)
        self.pub_lot.publish(lot_to_msg(self.lot))
        self.world: World | None = None
        self.episode = 0  # the running episode's id (set by _new_episode)
        self.seed = self.p["seed"]
        self.reactive = self.p["reactive"]
        self.started = False  # step 0 published
        self.subscribers_since: float | None = None  # when the subscribers step 0 waits for were first all there
        self.last_pub_wall = 0.0
        if self.p["autostart"]:
            self._new_episode(self.seed, self.reactive)
        if self.lockstep:
            self.timer = self.create_timer(0.05, self._lockstep_tick)
        else:
            self.timer = self.create_timer(self.dt, self._realtime_tick)
        self.get_logger().info(
            f"avp_sim up: lot '{self.lot.name}' ({self.lot.n_spots} spots), mode {self.p['mode']}, dt {self.dt}"
        )

    # ---------------------------------------------------------------- episodes
    def _new_episode(self, seed: int, reactive: bool, scenario: tuple[str, object] | None = None) -> World:
        world = make_world(self.lot, self.p, seed, reactive, scenario_data=scenario)
        if world.egos.n_auto != len(self.egos):
            raise ValueError(f"scenario: egos: {world.egos.n_auto} egos, but this simulator drives "
                             f"{len(self.egos)} (parameter egos.count)")
        self.world = world
        # the episode id every message of this episode carries (avp_common.msg_auth; docs/bad_input.md row 51): the
        # wall clock in ns, strictly increasing, so that a replay of an earlier episode (or of an earlier run) is older
        self.episode = max(time.time_ns(), self.episode + 1)
        seed, reactive = self.world.scenario.seed, self.world.scenario.reactive
        self.seed, self.reactive = seed, reactive
        self.started = False
        for ch in self.egos:
            ch.reset()
        for d in self.drivers:
            d.latest = None
        self.debug_step = -1  # last step whose ground truth went out (a re-send repeats only the observation)
        if not self.sensing.exact:  # same seed, same noise (avp_sensing.noisy)
            self.sensor = NoisySensor(self.sensing, seed, float(world.caster.region_range.max()))
            self.sensed = None
        dyn = [(v.id, v.target_spot_id, v.maneuver, v.passiveness) for v in self.world.scenario.dynamic_vehicles()]
        self.get_logger().info(f"episode seed={seed} reactive={reactive}: dynamic vehicles {dyn}")
        return self.world

    def _on_reset(self, req: ResetEpisode.Request, resp: ResetEpisode.Response) -> ResetEpisode.Response:
        try:
            scenario = requested_scenario(req.scenario_file, req.scenario_yaml, self.scenario_dirs,
                                          self.p["scenario_max_bytes"])
            w = self._new_episode(int(req.seed), bool(req.reactive), scenario)
            if not self.lockstep:
                self._publish_step()
            resp.success, resp.message, resp.n_vehicles = True, "ok", len(w.scenario.vehicles)
        except Exception as exc:  # noqa: BLE001 - any bad request is answered, the node keeps running
            resp.success, resp.message = False, f"reset_episode: {exc}"
            self.reject(resp.message)  # a stream of bad requests: one line a second per reason
        return resp

    # ---------------------------------------------------------------- stepping
    def _publish_step(self, only: list[int] | None = None) -> None:
        """Step k's messages: ground truth and markers once, the statuses, and the observation of every driving ego
        (of the egos ``only``: a lock-step re-send)."""
        w = self.world
        assert w is not None
        stamp = step_to_time(w.step_index, self.dt)
        self.pub_clock.publish(Clock(clock=stamp))
        first = w.step_index != self.debug_step  # one ground-truth record per step, even when the step is re-sent
        if first:  # before the observation's ray casting, so that it leaves as soon as the step is done
            self.debug_step = w.step_index
            self.pub_gt.publish(self._ground_truth_msg(w, stamp))
            if self.pub_braking_for is not None:
                self.pub_braking_for.publish(braking_for_msg(w, stamp))
        obs = w.observe(0)
        if first:
            if self.p["publish_markers"]:  # built only for a subscriber: ~30 ms a step on the DLP lot
                if self.pub_markers.get_subscription_count():
                    self.pub_markers.publish(world_markers(self.lot, w, obs, stamp))
                if self.pub_scan.get_subscription_count():
                    self.pub_scan.publish(self._scan_msg(obs, stamp))
        self.pub_status.publish(self._status_msg(w, stamp))
        driving = w.egos.driving
        for ch in self.egos:
            if ch.pub_status is not None:
                ch.pub_status.publish(self._status_msg(w, stamp, ch.index))
            if driving[ch.index] and (only is None or ch.index in only):
                if self.sensor is not None:
                    self._publish_sensed(ch, w, obs, stamp)
                    continue
                o = obs if ch.index == 0 else w.observe(ch.index)
                ch.pub_obs.publish(observation_to_msg(o, with_episode("map", self.episode)))
        for d in self.drivers:  # a driven car's own record: the agents it made brake, its collisions (docs/teleop.md)
            d.pub_status.publish(self._status_msg(w, stamp, d.slot))
        self.last_pub_wall = time.monotonic()
        self.started = True

    def _publish_sensed(self, ch: EgoChannel, w: World, obs, stamp) -> None:
        """Noisy sensing: the frame (sensing/observation: no vehicles, no pedestrians, the estimated ego pose, the
        spots as read) and its detections (sensing/detections), the same again for a re-sent step."""
        if self.sensed is None or self.sensed[0] != w.step_index:
            self.sensed = (w.step_index, self.sensor.sense(w, 0, obs))
        f = self.sensed[1]
        frame = Observation(step=f.step, dt=f.dt, ego_pose=f.ego_pose, ego_length=f.ego_length,
                            ego_width=f.ego_width, ego_speed=f.ego_speed, vacant_spot_ids=f.vacant_spot_ids,
                            occupied_spot_ids=f.occupied_spot_ids, ray_angle_min=f.ray_angle_min,
                            ray_angle_increment=f.ray_angle_increment, ray_ranges=f.ray_ranges,
                            ego_covariance=f.ego_covariance)
        frame_id = with_episode("map", self.episode)
        self.pub_detections.publish(detections_to_msg(f.vehicles, f.pedestrians, Header(stamp=stamp,
                                                                                       frame_id=frame_id)))
        ch.pub_obs.publish(observation_to_msg(frame, frame_id))

    def _lockstep_tick(self) -> None:
        w = self.world
        if w is None or w.done:
            return
        if not self.started:
            n_subs = min(ch.pub_obs.get_subscription_count() for ch in self.egos)
            n_cmd = min(self.count_publishers(ch.cmd_topic) for ch in self.egos)
            n_debug = self.pub_gt.get_subscription_count()
            if self.p["wait_for_subscribers"]:
                if (n_subs < self.p["min_subscribers"] or n_cmd < 1
                        or n_debug < self.p["min_debug_subscribers"]):
                    self.subscribers_since = None
                    return
                if self.subscribers_since is None:
                    self.subscribers_since = time.monotonic()
                if time.monotonic() - self.subscribers_since < SUBSCRIBER_SETTLE_S:
                    return  # our writers have matched them; their readers may still be matching ours
            self._publish_step()
            return
        while not w.done and not w.egos.driving.any():  # K egos: none in the lot drives (one parked, the next is
            w.step_all([(0.0, 0.0)] * len(self.egos))  # not in yet): the lot steps without commands
            self._publish_step()
        if w.done:
            return
        if time.monotonic() - self.last_pub_wall > self.p["lockstep_timeout"]:
            late = [ch for ch in self.egos if w.egos.driving[ch.index] and ch.pending is None]
            topics = ", ".join(ch.cmd_topic for ch in late)
            who = "" if len(self.egos) == 1 else f" from ego {', '.join(str(ch.index) for ch in late)}"
            self.get_logger().warning(
                f"lock-step: no command stamped step {w.step_index}{who} on {topics} for "
                f"{self.p['lockstep_timeout']} s; re-sending the observation"
            )
            self._publish_step([ch.index for ch in late])

    def _realtime_tick(self) -> None:
        w = self.world
        if w is None or w.done:
            return
        if not self.started:
            self._publish_step()
            return
        first = self.egos[0].latest_cmd
        if w.step_index == 0 and self.p["realtime_wait_first_command"] and (
                first is None or first[3] != step_to_ns(0, self.dt)):
            # the clock starts with the ego's first answer. Until then step 0 is re-sent whole — observation, ground
            # truth, markers — so that a recorder, monitor or viewer whose reader matches our volatile writers late
            # (DDS discovery) still gets step 0; every consumer keys ground truth by step (docs/graph.md, real time)
            self.debug_step = -1
            self._publish_step()
            return
        cmds = []
        driving = w.egos.driving
        for ch in self.egos:
            v, om, fresh = 0.0, 0.0, False
            if ch.latest_cmd is not None:
                cv, com, wall, stamp = ch.latest_cmd
                lag = (step_to_ns(w.step_index, self.dt) - stamp) / step_to_ns(1, self.dt)  # steps behind
                if time.monotonic() - wall <= self.p["command_watchdog"] and 0 <= lag <= self.p["command_max_lag"]:
                    v, om, fresh = cv, com, True
            if driving[ch.index]:
                self._report_hold(ch, w.step_index, fresh)
            cmds.append((v, om))
        now = time.monotonic()
        cmds += [d.command(now, self.p["drivers.watchdog"]) for d in self.drivers]  # step_all clamps them (eq. 1)
        w.step_all(cmds)
        self._publish_step()

    def _report_hold(self, ch: EgoChannel, k: int, fresh: bool) -> None:
        """Real time: one line when an ego starts holding still for want of a current command (a hung or dead
        planner, or one waiting for its inputs), one when commands come again."""
        if not fresh and ch.holding_since is None and ch.started_moving:
            ch.holding_since = k
            self.get_logger().warning(
                f"{ch.cmd_topic}: no current command for step {k} (command_watchdog "
                f"{self.p['command_watchdog']} s, command_max_lag {self.p['command_max_lag']}); the ego holds still")
        elif fresh and ch.holding_since is not None:
            self.get_logger().info(f"{ch.cmd_topic}: commands again at step {k} after "
                                   f"{k - ch.holding_since} held steps")
            ch.holding_since = None
        ch.started_moving |= fresh

    def _on_driver(self, j: int, v: float, om: float) -> None:
        """Driven car j's newest command (applied at the next step, clamped to eq. (1)'s limits)."""
        if not (math.isfinite(v) and math.isfinite(om)):
            self.reject(f"{self.drivers[j].sub.topic_name}: command with NaN/inf (v={v}, omega={om}) dropped")
            return
        self.drivers[j].latest = (v, om, time.monotonic())

    def _on_cmd(self, index: int, msg: TwistStamped) -> None:
        ch = self.egos[index]
        v, om = float(msg.twist.linear.x), float(msg.twist.angular.z)
        if not (math.isfinite(v) and math.isfinite(om)):
            self.reject(f"{ch.cmd_topic}: command with NaN/inf (v={v}, omega={om}) dropped")
            return
        w = self.world
        if w is None or w.done or not w.egos.driving[index]:
            return
        if episode_of(msg.header.frame_id) != self.episode:  # an answer to another episode's observation (a replay)
            self.reject_warn(f"{ch.cmd_topic}: command of another episode than the running one (a "
                             "replay, or an answer to the episode before a reset); dropped")
            return
        expected = step_to_ns(w.step_index, self.dt)
        got = time_to_ns(msg.header.stamp)
        if not self.lockstep:
            if got > expected:
                self.reject_warn(f"{ch.cmd_topic}: command stamped {got} ns is ahead of step {w.step_index}; dropped")
                return
            if ch.latest_cmd is None or got >= ch.latest_cmd[3]:  # never replaced by an older answer
                ch.latest_cmd = (v, om, time.monotonic(), got)
            return
        if not self.started or got != expected:
            if got > expected:
                self.reject_warn(f"{ch.cmd_topic}: command stamped {got} ns is ahead of step {w.step_index}; dropped")
            return  # stale commands (re-sent observations) are ignored
        ch.pending = (v, om)
        driving = w.egos.driving
        if any(driving[c.index] and c.pending is None for c in self.egos):
            return  # lock-step waits for every driving ego's answer to step k
        w.step_all([c.pending or (0.0, 0.0) for c in self.egos])
        for c in self.egos:
            c.pending = None
        self._publish_step()
        if w.done:
            self.get_logger().info(f"episode seed={self.seed} ended: {w.status} {w.metrics.as_dict()}")

    # ---------------------------------------------------------------- messages
    def _status_msg(self, w: World, stamp, ego: int | None = None) -> EpisodeStatus:
        """The lot's status with ego 0's metrics, or (``ego``) ego i's status and metrics."""
        m = w.metrics if ego is None else w.egos.metrics[ego]
        msg = EpisodeStatus()
        msg.header.stamp = stamp
        msg.step = w.step_index
        msg.sim_time = w.step_index * self.dt
        msg.dt = float(self.dt)
        msg.t_final = float(w.config.t_final)
        msg.seed = int(self.seed)
        msg.reactive = bool(self.reactive)
        msg.state = _STATE[w.status if ego is None else w.egos.status[ego]]
        msg.lock_step = self.lockstep
        mm = msg.metrics
        mm.success, mm.collision, mm.collision_with = m.success, m.collision, m.collision_with
        mm.collision_at_fault = bool(m.collision_at_fault)
        mm.spot_stolen, mm.parked_spot_id = m.spot_stolen, int(m.parked_spot_id)
        mm.interrupted_steps, mm.interrupted_agent_steps = int(m.interrupted_steps), int(m.interrupted_agent_steps)
        mm.parking_time, mm.steps = float(m.parking_time), int(m.steps)
        return msg

    def _ground_truth_msg(self, w: World, stamp) -> GroundTruth:
        msg = GroundTruth()
        msg.header.stamp = stamp
        msg.header.frame_id = "map"
        msg.step = w.step_index
        ego = AgentState(id=0, kind=AgentState.KIND_EGO, length=w.scenario.ego.length, width=w.scenario.ego.width,
                         target_spot_id=-1)
        ego.pose = Pose2D(x=float(w.ego[0]), y=float(w.ego[1]), theta=float(w.ego[2]))
        agents = [ego]
        for j in w.egos.others(0):  # K egos: the others in the lot, id = their index; driven car j: KIND_DRIVEN, j
            driven = bool(w.egos.is_driver[j])
            e = AgentState(id=int(j - w.egos.n_auto if driven else j),
                           kind=AgentState.KIND_DRIVEN if driven else AgentState.KIND_EGO, length=w.egos.length,
                           width=w.egos.width, target_spot_id=-1)
            pose = w.egos.poses[j]
            e.pose = Pose2D(x=float(pose[0]), y=float(pose[1]), theta=float(pose[2]))
            agents.append(e)
        # braking: for ego 0 (the message's "the ego"); with one car in the lot the same as w.braking
        braking = w.braking if w.egos.count == 1 else w.braking_for[:, 0]
        for i in range(len(w.states)):
            a = AgentState(id=int(w.vehicle_ids[i]), kind=AgentState.KIND_VEHICLE, length=float(w.vehicle_dims[i, 0]),
                           width=float(w.vehicle_dims[i, 1]), is_static=not bool(w.is_dynamic[i]),
                           braking=bool(braking[i]), target_spot_id=int(w.target_spot[i]))
            a.pose = Pose2D(x=float(w.states[i, 0]), y=float(w.states[i, 1]), theta=float(w.states[i, 2]))
            agents.append(a)
        for i in range(len(w.ped_pos)):
            a = AgentState(id=int(w.ped_ids[i]), kind=AgentState.KIND_PEDESTRIAN, radius=float(w.ped_radii[i]),
                           braking=bool(w.ped_braking[i]), target_spot_id=-1)
            a.pose = Pose2D(x=float(w.ped_pos[i, 0]), y=float(w.ped_pos[i, 1]), theta=0.0)
            agents.append(a)
        msg.agents = agents
        occupied, _ = w.occupancy()
        msg.occupied_spot_ids = [int(i) for i in self.lot.spot_ids[occupied]]
        return msg

    def _scan_msg(self, obs, stamp) -> LaserScan:
        scan = LaserScan()
        scan.header.stamp = stamp
        scan.header.frame_id = "base_link"  # REP-105: the ego's body frame (the scene node's /tf)
        scan.angle_min = float(obs.ray_angle_min)
        scan.angle_increment = float(obs.ray_angle_increment)
        scan.angle_max = float(obs.ray_angle_min + obs.ray_angle_increment * (len(obs.ray_ranges) - 1))
        scan.range_min = 0.0
        scan.range_max = float(np.max(obs.ray_ranges)) if len(obs.ray_ranges) else 0.0
        scan.ranges = np.asarray(obs.ray_ranges, dtype=np.float32)
        return scan


def main(args=None) -> int:
    return run_node(SimNode, "avp_sim", args)


if __name__ == "__main__":
    sys.exit(main())

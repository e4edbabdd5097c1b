"""A graph observer (debug side only): collects ground truth and status to write metrics and pictures, and
measures the closed-loop step time of the live graph.

**Closed-loop step time** (sense → command; target p95 <= 100 ms): for every step k, the wall time from the simulator
publishing observation k to the command answering it (stamped t_k) arriving — the DDS *source timestamp* of
observation k (taken by the simulator's writer; in lock-step, of its last re-send before the answer) to the DDS
*reception timestamp* of the first command stamped t_k at this node's reader (taken by the middleware's receive
thread, so it does not depend on how busy this process is). Both clocks are the same machine's system clock. In
real time (sim ``mode: realtime``) a command arriving after observation k+1 was sent comes too late to be used
(``command_max_lag`` 0): counted as ``late_steps``. With several egos each has its own
(:class:`~avp_monitor.step_timer.StepTimer` on ``ego<i>/observation`` and ``ego<i>/cmd``): the figures cover every
ego's steps, and ``per_ego`` gives each ego's.

Under a flood (docs/bad_input.md row 48) the figure stays honest: ``observation`` and ``cmd`` are taken only with a
valid tag (``avp_common.msg_auth``, the graph's key), and a copy of an observation within
``RESEND_ANSWER_INTERVAL`` of the first is a duplicate, not a lock-step re-send.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from geometry_msgs.msg import TwistStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message

from avp_common.conversions import observation_from_msg
from avp_common.drain import draining_subscription
from avp_common.msg_auth import ego_scope, load_key, scoped_key, verify
from avp_common.qos import QUIET_READER, STATUS
from avp_common.received import stamp_ns
from avp_monitor.step_timer import StepTimer, summary_ms
from avp_msgs.msg import AgentState, EpisodeStatus, GroundTruth, Observation, PredictedTrajectoryArray, SpotBeliefs

#: reader side of the metric streams: a whole episode (t_f = 100 s at dt = 0.1 s, 1000 steps) may queue while the
#: monitor is busy (the writer of debug/ground_truth keeps 300: avp_common.qos.GROUND_TRUTH; compatible QoS)
GROUND_TRUTH_QOS = QoSProfile(depth=1000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.VOLATILE)

STATE_NAMES = {EpisodeStatus.STATE_IDLE: "idle", EpisodeStatus.STATE_RUNNING: "running",
               EpisodeStatus.STATE_SUCCESS: "success", EpisodeStatus.STATE_COLLISION: "collision",
               EpisodeStatus.STATE_TIMEOUT: "timeout"}


class EpisodeMonitor(Node):
    def __init__(self, namespace: str = "/avp", egos: int = 1) -> None:
        super().__init__("avp_monitor", namespace=namespace)
        self.ego_status: dict[int, EpisodeStatus] = {}  # several egos: ego i's own status (ego<i>/episode_status)
        for i in range(egos if egos > 1 else 0):
            self.create_subscription(EpisodeStatus, f"ego{i}/episode_status",
                                     lambda m, i=i: self.ego_status.__setitem__(i, m), STATUS,
                                     event_callbacks=QUIET_READER)
        self.gt: dict[int, GroundTruth] = {}
        self.status: EpisodeStatus | None = None
        self._last_obs_raw: bytes | None = None  # ego 0's newest observation, deserialised when read (last_obs)
        #: each ego's step times (one ego: ``observation``/``cmd``; several: ``ego<i>/observation``/``ego<i>/cmd``)
        self.ego_timers = [StepTimer() for _ in range(max(1, egos))]
        # every step matters (metrics, step times, the DDS tests): deep reader queues ride out a busy CPU
        gt = self.create_subscription(GroundTruth, "debug/ground_truth", self._on_gt, GROUND_TRUTH_QOS,
                                      event_callbacks=QUIET_READER)
        self.create_subscription(EpisodeStatus, "episode_status", self._on_status, STATUS, event_callbacks=QUIET_READER)
        self.key = load_key()
        #: the readers whose every message counts (the step times read each ego's observation and cmd)
        self._must_match = [gt]
        for i, timer in enumerate(self.ego_timers):
            prefix = f"ego{i}/" if egos > 1 else ""
            key = scoped_key(self.key, ego_scope(prefix))  # what only ego i's own nodes can send
            self._must_match += [
                draining_subscription(self, Observation, f"{prefix}observation",
                                      self._tagged(self._obs_cb(i, timer), key), GROUND_TRUTH_QOS, with_info=True),
                draining_subscription(self, TwistStamped, f"{prefix}cmd",
                                      self._tagged(self._cmd_cb(timer), key), GROUND_TRUTH_QOS, with_info=True)]
        # per-node stage times of ego 0: when each node's output of step k left it (DDS source timestamps)
        self.stage_sent: dict[str, dict[int, int]] = {"beliefs": {}, "predictions": {}}
        prefix = "ego0/" if egos > 1 else ""
        for name, msg_type in (("beliefs", SpotBeliefs), ("predictions", PredictedTrajectoryArray)):
            draining_subscription(self, msg_type, f"{prefix}{name}",
                                  self._tagged(self._stage_cb(name), scoped_key(self.key, ego_scope(prefix))),
                                  GROUND_TRUTH_QOS, with_info=True)

    @property
    def obs_sent(self) -> dict[int, list[int]]:
        """Ego 0's observations: stamp [ns] -> DDS source timestamps [ns] (:class:`StepTimer`)."""
        return self.ego_timers[0].obs_sent

    @property
    def next_sent(self) -> dict[int, int]:
        return self.ego_timers[0].next_sent

    @property
    def cmd_received(self) -> dict[int, int]:
        return self.ego_timers[0].cmd_received

    def inputs_matched(self) -> bool:
        """Whether this monitor's readers of the ground truth and of every ego's observation and command have matched
        a writer: a volatile reader that matches after the episode started misses its first steps, and
        on a loaded machine matching can take seconds after discovery (a demo then measured 0 step times)."""
        return all(s.get_publisher_count() >= 1 for s in self._must_match)

    @property
    def last_obs(self) -> Observation | None:
        """Ego 0's newest observation (the rays of the picture)."""
        raw = self._last_obs_raw
        return deserialize_message(raw, Observation) if raw is not None else None

    def _stage_cb(self, name: str):
        def cb(stamp: int, raw: bytes, info) -> None:
            self.stage_sent[name].setdefault(stamp, int(info["source_timestamp"]))
        return cb

    @staticmethod
    def _tagged(callback, key: bytes):
        """``callback(stamp_ns, raw, info)`` for what the graph's own nodes sent (anything else is a foreign
        publisher's). The step times need only ``header.stamp``: read from the bytes, never a whole message built
        (an observation of the busy lot holds hundreds of poses; avp_common.received)."""
        def cb(raw: bytes, info) -> None:
            if verify(key, raw):
                callback(stamp_ns(raw), raw, info)
        return cb

    @staticmethod
    def _cmd_cb(timer: StepTimer):
        return lambda stamp, raw, info: timer.on_cmd(stamp, int(info["received_timestamp"]))

    def _obs_cb(self, i: int, timer: StepTimer):
        def cb(stamp: int, raw: bytes, info) -> None:
            if i == 0 and timer.restarts(stamp):
                for d in self.stage_sent.values():
                    d.clear()
            if timer.on_obs(stamp, int(info["source_timestamp"])) and i == 0:
                self._last_obs_raw = raw
        return cb

    def _on_gt(self, msg: GroundTruth) -> None:
        self.gt[int(msg.step)] = msg

    def _on_status(self, msg: EpisodeStatus) -> None:
        self.status = msg

    def step_times(self) -> tuple[np.ndarray, int]:
        """Every ego's closed-loop step times [s] together, and their late answers (:meth:`StepTimer.step_times`)."""
        parts = [t.step_times() for t in self.ego_timers]
        return np.concatenate([p[0] for p in parts]), sum(p[1] for p in parts)

    def latency_dict(self, mode: str) -> dict:
        """Closed-loop step-time figures for metrics.json (module docstring): milliseconds, over every ego's steps;
        with several egos also per ego (``per_ego``)."""
        lat, late = self.step_times()
        out = {"definition": "per step: DDS source timestamp of observation k (simulator) -> DDS reception timestamp "
                             "of the first command stamped t_k (wall clock)",
               "sim_mode": mode, "steps": int(len(lat)), "target_p95_ms": 100.0, **summary_ms(lat)}
        if mode == "realtime":
            out["late_steps"] = int(late)  # answered after observation k+1 was sent: not used, the ego held still
        if len(self.ego_timers) > 1:
            out["per_ego"] = []
            for i, t in enumerate(self.ego_timers):
                lat_i, late_i = t.step_times()
                out["per_ego"].append({"ego": i, "steps": int(len(lat_i)), **summary_ms(lat_i),
                                       **({"late_steps": int(late_i)} if mode == "realtime" else {})})
        stages = self.stage_times()
        if stages:
            out["stages_ms"] = stages
        return out

    def stage_times(self) -> dict[str, dict[str, float]]:
        """Per node, median and p95 [ms] over the steps of: belief node (observation k sent -> beliefs k sent),
        prediction node (beliefs k sent -> predictions k sent), planner (predictions k sent -> command k received);
        each includes one DDS hop. Steps where a node's output is missing (a method without it) are left out."""
        b, pr = self.stage_sent["beliefs"], self.stage_sent["predictions"]
        first = {k: v[0] for k, v in self.obs_sent.items()}
        spans = {"belief_node": [(b[k] - first[k]) for k in first if k in b],
                 "prediction_node": [(pr[k] - b[k]) for k in b if k in pr],
                 "planner": [(self.cmd_received[k] - pr[k]) for k in pr if k in self.cmd_received]}
        return {name: {"median_ms": round(float(np.median(v)) * 1e-6, 2),
                       "p95_ms": round(float(np.percentile(v, 95)) * 1e-6, 2), "steps": len(v)}
                for name, v in spans.items() if v}

    @property
    def finished(self) -> bool:
        return self.status is not None and self.status.state not in (EpisodeStatus.STATE_RUNNING,
                                                                       EpisodeStatus.STATE_IDLE)

    def ego_trajectory(self, ego: int = 0) -> np.ndarray:
        """Ego ``ego``'s poses, step by step, from the step it is first in the lot (K egos: its id is its index)."""
        out = []
        for k in sorted(self.gt):
            a = next((a for a in self.gt[k].agents if a.kind == AgentState.KIND_EGO and int(a.id) == ego), None)
            if a is not None:
                out.append([a.pose.x, a.pose.y, a.pose.theta])
        return np.array(out).reshape(-1, 3)

    def vehicle_trajectories(self) -> dict:
        out: dict[int, dict] = {}
        for k in sorted(self.gt):
            for a in self.gt[k].agents:
                if a.kind != AgentState.KIND_VEHICLE:
                    continue
                d = out.setdefault(int(a.id), {"traj": [], "dims": (a.length, a.width), "dynamic": not a.is_static,
                                               "target": int(a.target_spot_id)})
                d["traj"].append([a.pose.x, a.pose.y, a.pose.theta])
        return out

    def ego_states(self) -> list[dict]:
        """Several egos: each ego's state and metrics from its own episode status (``egos`` given)."""
        out = []
        for i in sorted(self.ego_status):
            m = self.ego_status[i].metrics
            out.append({"state": STATE_NAMES.get(self.ego_status[i].state, "?"), "success": bool(m.success),
                        "collision": bool(m.collision), "collision_with": m.collision_with,
                        "parked_spot_id": int(m.parked_spot_id),
                        "parking_time": None if math.isnan(m.parking_time) else float(m.parking_time),
                        "interrupted_steps": int(m.interrupted_steps)})
        return out

    def metrics_dict(self) -> dict:
        s = self.status
        assert s is not None
        m = s.metrics
        return {
            "seed": int(s.seed), "reactive": bool(s.reactive), "state": STATE_NAMES.get(s.state, str(s.state)),
            "success": bool(m.success), "collision": bool(m.collision), "collision_with": m.collision_with,
            "collision_at_fault": bool(m.collision_at_fault),
            "spot_stolen": bool(m.spot_stolen), "parked_spot_id": int(m.parked_spot_id),
            "interrupted_steps": int(m.interrupted_steps), "interrupted_agent_steps": int(m.interrupted_agent_steps),
            "parking_time": None if math.isnan(m.parking_time) else float(m.parking_time),
            "steps": int(m.steps), "sim_time": float(s.sim_time), "lock_step": bool(s.lock_step),
            "ground_truth_steps_received": len(self.gt),
        }

    def write(self, lot, out_dir: Path, extra: dict | None = None) -> dict:
        from avp_viz.render import render_episode

        out_dir.mkdir(parents=True, exist_ok=True)
        metrics = {**self.metrics_dict(), **(extra or {})}
        (out_dir / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
        last_gt = self.gt[max(self.gt)] if self.gt else None
        occupied = set(int(i) for i in last_gt.occupied_spot_ids) if last_gt else set()
        last_obs = self.last_obs
        rays = observation_from_msg(last_obs).ray_endpoints() if last_obs is not None else None
        dims = {int(a.id): (a.length, a.width) for a in last_gt.agents if a.kind == AgentState.KIND_EGO} \
            if last_gt else {}
        ego_dims = dims.get(0) or next(iter(dims.values()), (4.6, 1.85))
        outcome = f"{metrics['state']} at t={metrics['sim_time']:.1f}s"
        others = {}
        if len(self.ego_status) > 1:  # several egos: each drawn in its colour; the title counts the parked ones
            others = {i: (self.ego_trajectory(i), dims.get(i, (4.6, 1.85))) for i in sorted(self.ego_status) if i}
            parked = sum(s.metrics.success for s in self.ego_status.values())
            outcome = f"{parked} of {len(self.ego_status)} egos parked, t={metrics['sim_time']:.1f}s"
        title = f"seed {metrics['seed']} {'reactive' if metrics['reactive'] else 'non-reactive'}: {outcome}"
        render_episode(lot, self.ego_trajectory(), ego_dims, self.vehicle_trajectories(), occupied, rays, title,
                       out_dir / "episode.png", other_egos=others)
        return metrics

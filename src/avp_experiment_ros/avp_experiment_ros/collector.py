"""The collector node of ``avp experiment --transport ros`` (:mod:`.ros_transport`): a debug-side observer of one
episode at a time, never part of the ego. It records ``episode_status``, ``debug/ground_truth``, the prediction
node's ``predictions``, the planner's ``decision`` (timings) and the DDS source timestamps of ``observation`` and
``predictions``, and builds the episode record with the in-process transport's function."""

from __future__ import annotations

import numpy as np
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from avp_common.conversions import predictions_from_msg
from avp_common.qos import QUIET_READER, STATUS
from avp_episode.metrics import episode_record, prediction_errors
from avp_msgs.msg import (
    AgentState,
    DecisionTrace,
    EpisodeStatus,
    GroundTruth,
    Observation,
    PlannerDecision,
    PredictedTrajectoryArray,
)

NAMESPACE = "/avp"
STATE_NAMES = {2: "success", 3: "collision", 4: "timeout"}  # EpisodeStatus.STATE_*


def deep_qos(depth: int = 2000) -> QoSProfile:
    """Reliable, volatile, ``depth`` deep: the simulator only waits for the egos, so a deep reader history keeps every
    step even when this process falls behind for a while (with the graph's depth 10 a busy CPU loses messages here)."""
    return QoSProfile(depth=depth, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


def with_perception(timings: dict, t_obs: int | None, t_preds: int | None) -> dict:
    """A step's planner ``timings`` with the perception's critical path added to the spot-selection time: the DDS
    source timestamps [ns] of its predictions minus its observation (belief node, prediction node, two hops)."""
    t = dict(timings)
    if t_obs is not None and t_preds is not None:
        t["perception_time"] = max(0.0, (t_preds - t_obs) * 1e-9)
        t["spot_selection_time"] += t["perception_time"]
    return t


def status_metrics(m) -> dict:
    """The §VI-B metrics of an avp_msgs/EpisodeMetrics as the records' dict (as EpisodeMetrics.as_dict in process)."""
    return {"success": bool(m.success), "collision": bool(m.collision), "collision_with": m.collision_with,
            "collision_at_fault": bool(m.collision_at_fault), "spot_stolen": bool(m.spot_stolen),
            "parked_spot_id": int(m.parked_spot_id), "interrupted_steps": int(m.interrupted_steps),
            "interrupted_agent_steps": int(m.interrupted_agent_steps), "parking_time": float(m.parking_time),
            "steps": int(m.steps)}


class EpisodeCollector(Node):
    """Debug-side observer of one episode at a time (never part of the ego)."""

    def __init__(self, lot: dict | None = None) -> None:
        super().__init__("avp_experiment", namespace=NAMESPACE)
        self.lot = lot  # the lot record of every episode (metrics.lot_record)
        self.begin(-1, False)
        deep = deep_qos()
        self.create_subscription(GroundTruth, "debug/ground_truth", self._on_gt, deep, event_callbacks=QUIET_READER)
        self.create_subscription(EpisodeStatus, "episode_status", self._on_status, STATUS, event_callbacks=QUIET_READER)
        self.create_subscription(PredictedTrajectoryArray, "predictions", self._on_preds, deep,
                                 event_callbacks=QUIET_READER)
        self.create_subscription(PlannerDecision, "decision", self._on_decision, deep, event_callbacks=QUIET_READER)
        self.create_subscription(Observation, "observation", self._on_obs, deep, event_callbacks=QUIET_READER)
        # the planner's decision trace, when it publishes one (a user's planner may not)
        self.create_subscription(DecisionTrace, "avp_planner/debug/decision", self._on_trace, deep,
                                 event_callbacks=QUIET_READER)
        self.kind_vehicle = AgentState.KIND_VEHICLE
        self.terminal = (EpisodeStatus.STATE_SUCCESS, EpisodeStatus.STATE_COLLISION,
                         EpisodeStatus.STATE_TIMEOUT)

    def begin(self, seed: int, reactive: bool) -> None:
        self.seed, self.reactive = seed, reactive
        self.status = None
        self.gt: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self.ego: dict[int, tuple[float, float, float]] = {}  # step -> the ego's pose (ground truth)
        self.preds: dict[int, list] = {}
        self.timings: dict[int, dict] = {}
        self.t_obs: dict[int, int] = {}  # step -> DDS source timestamp [ns] of the observation (first sent)
        self.t_preds: dict[int, int] = {}  # ... of the predictions
        self.traces: dict[int, tuple] = {}  # step -> avp_planner.trace_msg.trace_from_msg

    def _on_gt(self, msg) -> None:
        ego = [a.pose for a in msg.agents if a.kind == AgentState.KIND_EGO]
        if ego:
            self.ego[int(msg.step)] = (ego[0].x, ego[0].y, ego[0].theta)
        veh = [a for a in msg.agents if a.kind == self.kind_vehicle]
        self.gt[int(msg.step)] = (np.array([a.id for a in veh], dtype=np.int64),
                                  np.array([[a.pose.x, a.pose.y, a.pose.theta] for a in veh]).reshape(-1, 3))

    def _on_status(self, msg) -> None:
        if int(msg.seed) == self.seed and bool(msg.reactive) == self.reactive:
            self.status = msg

    def _on_obs(self, msg, info) -> None:
        self.t_obs.setdefault(int(msg.step), int(info["source_timestamp"]))

    def _on_preds(self, msg, info) -> None:
        self.preds[int(msg.step)] = [p for p in predictions_from_msg(msg) if not p.is_pedestrian]
        self.t_preds.setdefault(int(msg.step), int(info["source_timestamp"]))

    def _on_decision(self, msg) -> None:
        self.timings[int(msg.step)] = {"spot_selection_time": float(msg.spot_selection_time),
                                       "path_planning_time": float(msg.path_planning_time)}

    def _on_trace(self, msg) -> None:
        from avp_planner.trace_msg import trace_from_msg

        self.traces[int(msg.step)] = trace_from_msg(msg)

    def step_timings(self, k: int) -> dict:
        """The planner's timings of step k with the perception's critical path (see the module docstring)
        added to the spot-selection time."""
        return with_perception(self.timings[k], self.t_obs.get(k), self.t_preds.get(k))

    @property
    def ended(self) -> bool:
        return self.status is not None and self.status.state in self.terminal

    def missing(self) -> dict[str, list[int]]:
        """Steps of the ended episode whose ground truth / predictions / decision have not arrived."""
        n = int(self.status.metrics.steps)
        out = {name: [k for k in range(m) if k not in d] for name, d, m in
               (("ground_truth", self.gt, n + 1), ("predictions", self.preds, n), ("decision", self.timings, n))}
        if self.traces:  # the planner publishes its trace: wait for every step's
            out["decision_trace"] = [k for k in range(n) if k not in self.traces]
        return out

    def ego_publishers_ready(self) -> bool:
        return all(self.count_publishers(f"{NAMESPACE}/{t}") >= 1 for t in ("predictions", "decision"))

    def record(self, method: str, horizon: float, wall_s: float) -> dict:
        s = self.status
        m = s.metrics
        n = int(m.steps)
        ids = self.gt[0][0]
        for k in range(n + 1):
            if not np.array_equal(self.gt[k][0], ids):
                raise RuntimeError(f"ground truth of step {k} lists other vehicles than step 0")
        gt = np.stack([self.gt[k][1] for k in range(n + 1)])
        ade, fde = prediction_errors({k: self.preds[k] for k in range(n)}, gt, ids, float(s.dt), horizon)
        metrics = status_metrics(m)
        return episode_record(method=method, seed=self.seed, reactive=self.reactive,
                              status=STATE_NAMES.get(int(s.state), str(s.state)), metrics=metrics, min_ade=ade,
                              min_fde=fde, step_timings=[self.step_timings(k) for k in range(n)], horizon=horizon,
                              transport="ros", wall_s=wall_s, lot=self.lot,
                              ego_poses=np.array([self.ego[k] for k in range(n + 1)]),
                              decision_trace=self._trace_summary(n, float(s.dt)))

    def _trace_summary(self, n: int, dt: float) -> dict | None:
        """The episode's trace summary from the planner's ~/debug/decision (as the in-process runner's)."""
        from avp_motion.trace import DecisionTrace as Trace

        if not all(k in self.traces for k in range(n)):
            return None
        trace = Trace(dt)
        for k in range(n):
            trace.add_step(*self.traces[k])
        return trace.summary()

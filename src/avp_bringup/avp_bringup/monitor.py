"""A graph observer (debug side only): collects ground truth and status to write metrics and pictures."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from avp_common.conversions import observation_from_msg
from avp_common.qos import DEBUG, STATUS
from avp_msgs.msg import AgentState, EpisodeStatus, GroundTruth, Observation

GROUND_TRUTH_QOS = QoSProfile(depth=1000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.VOLATILE)

STATE_NAMES = {EpisodeStatus.STATE_IDLE: "idle", EpisodeStatus.STATE_RUNNING: "running",
               EpisodeStatus.STATE_SUCCESS: "success", EpisodeStatus.STATE_COLLISION: "collision",
               EpisodeStatus.STATE_TIMEOUT: "timeout"}


class EpisodeMonitor(Node):
    def __init__(self, namespace: str = "/avp") -> None:
        super().__init__("avp_monitor", namespace=namespace)
        self.gt: dict[int, GroundTruth] = {}
        self.status: EpisodeStatus | None = None
        self._last_obs_raw: bytes | None = None
        # every ground-truth step matters (metrics, the DDS tests): a deep reader queue rides out a busy CPU
        self.create_subscription(GroundTruth, "debug/ground_truth", self._on_gt, GROUND_TRUTH_QOS)
        self.create_subscription(EpisodeStatus, "episode_status", self._on_status, STATUS)
        # only the last observation is used (rays in the picture): kept as CDR bytes, decoded once at the end
        self.create_subscription(Observation, "observation", self._on_obs, DEBUG, raw=True)

    def _on_gt(self, msg: GroundTruth) -> None:
        self.gt[int(msg.step)] = msg

    def _on_status(self, msg: EpisodeStatus) -> None:
        self.status = msg

    def _on_obs(self, raw: bytes) -> None:
        self._last_obs_raw = raw

    @property
    def last_obs(self) -> Observation | None:
        if self._last_obs_raw is None:
            return None
        from rclpy.serialization import deserialize_message

        return deserialize_message(self._last_obs_raw, Observation)

    @property
    def finished(self) -> bool:
        return self.status is not None and self.status.state not in (EpisodeStatus.STATE_RUNNING,
                                                                       EpisodeStatus.STATE_IDLE)

    def ego_trajectory(self) -> np.ndarray:
        steps = sorted(self.gt)
        out = []
        for k in steps:
            ego = next(a for a in self.gt[k].agents if a.kind == AgentState.KIND_EGO)
            out.append([ego.pose.x, ego.pose.y, ego.pose.theta])
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

    def metrics_dict(self) -> dict:
        s = self.status
        assert s is not None
        m = s.metrics
        return {
            "seed": int(s.seed), "reactive": bool(s.reactive), "state": STATE_NAMES.get(s.state, str(s.state)),
            "success": bool(m.success), "collision": bool(m.collision), "collision_with": m.collision_with,
            "spot_stolen": bool(m.spot_stolen), "parked_spot_id": int(m.parked_spot_id),
            "interrupted_steps": int(m.interrupted_steps), "interrupted_agent_steps": int(m.interrupted_agent_steps),
            "parking_time": None if math.isnan(m.parking_time) else float(m.parking_time),
            "steps": int(m.steps), "sim_time": float(s.sim_time), "lock_step": bool(s.lock_step),
            "ground_truth_steps_received": len(self.gt),
        }

    def write(self, lot, out_dir: Path, extra: dict | None = None) -> dict:
        from avp_bringup.render import render_episode

        out_dir.mkdir(parents=True, exist_ok=True)
        metrics = {**self.metrics_dict(), **(extra or {})}
        (out_dir / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
        last_gt = self.gt[max(self.gt)] if self.gt else None
        occupied = set(int(i) for i in last_gt.occupied_spot_ids) if last_gt else set()
        last_obs = self.last_obs
        rays = observation_from_msg(last_obs).ray_endpoints() if last_obs is not None else None
        ego = next(a for a in last_gt.agents if a.kind == AgentState.KIND_EGO) if last_gt else None
        title = (f"seed {metrics['seed']} {'reactive' if metrics['reactive'] else 'non-reactive'}: "
                 f"{metrics['state']} at t={metrics['sim_time']:.1f}s")
        render_episode(lot, self.ego_trajectory(), (ego.length, ego.width) if ego else (4.6, 1.85),
                       self.vehicle_trajectories(), occupied, rays, title, out_dir / "episode.png")
        return metrics

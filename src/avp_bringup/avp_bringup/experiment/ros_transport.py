"""``avp experiment --transport ros``: the same episodes through the live DDS graph.

Per method one graph is started (:func:`avp_bringup.graph.method_graph`: the simulator in lock-step with
``autostart`` off, the belief node, the prediction node and the planner, each configured from the method's
profile, wall-clock caps lifted), and each episode is started with the simulator's ``reset_episode`` service
(seed, reactive). A collector node in this process records what the runner needs and the ego never sees:
``episode_status`` (the simulator's §VI-B metrics), ``debug/ground_truth`` (every vehicle's state per step, for
minADE/minFDE), the prediction node's ``predictions``, the planner's ``decision`` (timings) and the publication
times of ``observation`` and ``predictions``. The record is built by the same function as in-process
(:func:`~.metrics.episode_record`), so both transports give identical records apart from the timings.

Timings: the perception runs in two other processes, so its share of the spot-selection time is measured on
the critical path — the DDS source timestamps of predictions k minus observation k (belief node, prediction
node and two hops) — and added to the planner's own spot-selection time from ``decision``. In-process timings
(``--transport inproc``) are pure compute and are the ones to compare with Table I. Slow (one episode at a time,
~10-20 ms per DDS round trip); meant for the equivalence test.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from avp_bringup.experiment.metrics import episode_record, prediction_errors
from avp_bringup.experiment.protocols import load_protocol
from avp_bringup.experiment.run_config import Key, RunConfig, run_profile, sim_values

NAMESPACE = "/avp"
DRAIN_S = 10.0  # wall seconds to wait for the last messages after the episode ended
STATE_NAMES = {2: "success", 3: "collision", 4: "timeout"}  # EpisodeStatus.STATE_*


def _collector_class():
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    from avp_common.conversions import predictions_from_msg
    from avp_common.qos import STATUS
    from avp_msgs.msg import (
        AgentState,
        EpisodeStatus,
        GroundTruth,
        Observation,
        PlannerDecision,
        PredictedTrajectoryArray,
    )

    class EpisodeCollector(Node):
        """Debug-side observer of one episode at a time (never part of the ego)."""

        def __init__(self) -> None:
            super().__init__("avp_experiment", namespace=NAMESPACE)
            self.begin(-1, False)
            # the simulator only waits for the ego: a deep reader history keeps every step even when this process
            # falls behind for a while (with the graph's depth 10 a busy CPU loses messages here)
            deep = QoSProfile(depth=2000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.VOLATILE)
            self.create_subscription(GroundTruth, "debug/ground_truth", self._on_gt, deep)
            self.create_subscription(EpisodeStatus, "episode_status", self._on_status, STATUS)
            self.create_subscription(PredictedTrajectoryArray, "predictions", self._on_preds, deep)
            self.create_subscription(PlannerDecision, "decision", self._on_decision, deep)
            self.create_subscription(Observation, "observation", self._on_obs, deep)
            self.kind_vehicle = AgentState.KIND_VEHICLE
            self.terminal = (EpisodeStatus.STATE_SUCCESS, EpisodeStatus.STATE_COLLISION,
                             EpisodeStatus.STATE_TIMEOUT)

        def begin(self, seed: int, reactive: bool) -> None:
            self.seed, self.reactive = seed, reactive
            self.status = None
            self.gt: dict[int, tuple[np.ndarray, np.ndarray]] = {}
            self.preds: dict[int, list] = {}
            self.timings: dict[int, dict] = {}
            self.t_obs: dict[int, int] = {}  # step -> DDS source timestamp [ns] of the observation (first sent)
            self.t_preds: dict[int, int] = {}  # ... of the predictions

        def _on_gt(self, msg) -> None:
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

        def step_timings(self, k: int) -> dict:
            """The planner's timings of step k with the perception's critical path (see the module docstring)
            added to the spot-selection time."""
            t = dict(self.timings[k])
            if k in self.t_obs and k in self.t_preds:
                t["perception_time"] = max(0.0, (self.t_preds[k] - self.t_obs[k]) * 1e-9)
                t["spot_selection_time"] += t["perception_time"]
            return t

        @property
        def ended(self) -> bool:
            return self.status is not None and self.status.state in self.terminal

        def missing(self) -> dict[str, list[int]]:
            """Steps of the ended episode whose ground truth / predictions / decision have not arrived."""
            n = int(self.status.metrics.steps)
            return {name: [k for k in range(m) if k not in d] for name, d, m in
                    (("ground_truth", self.gt, n + 1), ("predictions", self.preds, n), ("decision", self.timings, n))}

        @property
        def finished(self) -> bool:
            return self.ended and not any(self.missing().values())

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
            metrics = {"success": bool(m.success), "collision": bool(m.collision),
                       "collision_with": m.collision_with, "spot_stolen": bool(m.spot_stolen),
                       "parked_spot_id": int(m.parked_spot_id), "interrupted_steps": int(m.interrupted_steps),
                       "interrupted_agent_steps": int(m.interrupted_agent_steps),
                       "parking_time": float(m.parking_time), "steps": n}
            return episode_record(method=method, seed=self.seed, reactive=self.reactive,
                                  status=STATE_NAMES.get(int(s.state), str(s.state)), metrics=metrics, min_ade=ade,
                                  min_fde=fde, step_timings=[self.step_timings(k) for k in range(n)], horizon=horizon,
                                  transport="ros", wall_s=wall_s)

    return EpisodeCollector


def run_ros(keys: list[Key], cfg: RunConfig, on_record: Callable[[dict], None], log_dir: Path,
            timeout: float = 600.0, env: dict | None = None) -> None:
    """Run ``keys`` through the live graph, one method graph after the other (see the module docstring)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from avp_bringup.graph import Graph, method_graph
    from avp_bringup.services import call_once
    from avp_msgs.srv import ResetEpisode

    if not cfg.message_precision:
        raise ValueError("--float64-messages applies to --transport inproc only (the graph's messages are float32)")
    sim_p = sim_values(cfg)
    sim_extra = ({k: sim_p[k] for k in ("t_final", "dt", "t_hist")} | load_protocol(cfg.protocol).sim
                 | dict(cfg.sim_overrides))
    by_method: dict[str, list[Key]] = {}
    for k in keys:
        by_method.setdefault(k[0], []).append(k)
    rclpy.init()
    collector = _collector_class()()
    executor = SingleThreadedExecutor()
    executor.add_node(collector)
    client = collector.create_client(ResetEpisode, "reset_episode")
    try:
        for method, mkeys in by_method.items():
            nodes = method_graph(run_profile(method, cfg), deterministic=True, intent_weights=cfg.intent_weights,
                                 intent_seed=cfg.intent_seed, sim_extra={
                                     **sim_extra, "autostart": False, "publish_markers": False,
                                     "min_debug_subscribers": 1})
            graph = Graph(nodes, Path(log_dir) / method, env=env)
            graph.start()
            try:
                t0 = time.monotonic()
                # the simulator's step 0 waits for the ego's observation subscription; the ego's outputs must reach
                # us from step 0 on too: wait until its publishers are discovered (then a moment for matching)
                while not (client.wait_for_service(timeout_sec=0.2) and collector.ego_publishers_ready()):
                    executor.spin_once(timeout_sec=0.05)
                    _check_alive(graph, log_dir, method)
                    if time.monotonic() - t0 > 60:
                        raise RuntimeError(f"graph not up after 60 s (reset_episode service, pipeline publishers);"
                                           f" logs in {log_dir}/{method}")
                t1 = time.monotonic()
                while time.monotonic() - t1 < 0.5:
                    executor.spin_once(timeout_sec=0.05)
                for _, seed, mode in mkeys:
                    reactive = mode == "reactive"
                    collector.begin(seed, reactive)
                    t0 = time.monotonic()
                    try:  # sent once; the episode's own status also shows that the reset happened
                        res = call_once(client, ResetEpisode.Request(seed=int(seed), reactive=reactive),
                                        lambda s: executor.spin_once(timeout_sec=s),
                                        lambda: collector.status is not None, timeout=30.0)
                    except TimeoutError as exc:
                        raise RuntimeError(f"reset_episode(seed={seed}, reactive={reactive}) failed: {exc}") from None
                    if res is not None and not res.success:
                        raise RuntimeError(f"reset_episode(seed={seed}, reactive={reactive}) failed: {res.message}")
                    t_end = None
                    while not collector.finished:
                        executor.spin_once(timeout_sec=0.1)
                        _check_alive(graph, log_dir, method)
                        if collector.ended and t_end is None:
                            t_end = time.monotonic()
                        if t_end is not None and time.monotonic() - t_end > DRAIN_S:
                            missing = {k: v[:10] for k, v in collector.missing().items() if v}
                            raise RuntimeError(f"{method} seed {seed} {mode}: the episode ended but messages of steps "
                                               f"{missing} never arrived; logs in {log_dir}/{method}")
                        if time.monotonic() - t0 > timeout:
                            raise RuntimeError(f"{method} seed {seed} {mode}: no complete episode after {timeout} s "
                                               f"wall time; logs in {log_dir}/{method}")
                    on_record(collector.record(method, cfg.ade_horizon, time.monotonic() - t0))
            finally:
                graph.stop()
    finally:
        collector.destroy_node()
        rclpy.try_shutdown()


def _check_alive(graph, log_dir: Path, method: str) -> None:
    dead = {n: rc for n, rc in graph.poll().items() if rc is not None}
    if dead:
        raise RuntimeError(f"node(s) exited: {dead}; see {Path(log_dir) / method}/")

"""The collector of ``avp experiment --transport ros --egos K`` (avp_experiment_ros.transport): a debug-side
observer of one fleet episode at a time, never part of any ego.

It records the lot's ``episode_status`` (when the episode ends), ``debug/ground_truth`` (every vehicle and ego in the
lot per step), ``debug/braking_for`` (which ego each braking agent brakes for) and, per ego i in ``/avp/ego<i>``,
its ``episode_status``, its planner's ``decision`` and decision trace, and the DDS source timestamps of its
``observation`` and ``predictions``. :meth:`FleetCollector.records` then builds a record per ego with the in-process
fleet's fields (:func:`avp_episode.fleet.run_fleet_inproc`), its spots lost and the gridlock metric replayed
step by step with the same functions (:mod:`.fleet_metrics`), so both transports give the same records apart from
the timings.
"""

from __future__ import annotations

import numpy as np
from rclpy.node import Node

from avp_common.qos import QUIET_READER, STATUS
from avp_experiment_ros.collector import NAMESPACE, STATE_NAMES, deep_qos, status_metrics, with_perception
from avp_msgs.msg import (
    AgentState,
    BrakingFor,
    DecisionTrace,
    EpisodeStatus,
    GroundTruth,
    Observation,
    PlannerDecision,
    PredictedTrajectoryArray,
)

TERMINAL = (EpisodeStatus.STATE_SUCCESS, EpisodeStatus.STATE_COLLISION, EpisodeStatus.STATE_TIMEOUT)


class FleetCollector(Node):
    """Debug-side observer of one episode of ``k`` egos at a time (never part of an ego)."""

    def __init__(self, k: int, lot, lot_rec: dict | None = None) -> None:
        super().__init__("avp_experiment_fleet", namespace=NAMESPACE)
        self.k, self.lot, self.lot_rec = int(k), lot, lot_rec
        self.begin(-1, False)
        deep = deep_qos(4000)
        self.create_subscription(GroundTruth, "debug/ground_truth", self._on_gt, deep, event_callbacks=QUIET_READER)
        self.create_subscription(BrakingFor, "debug/braking_for", self._on_braking, deep, event_callbacks=QUIET_READER)
        self.create_subscription(EpisodeStatus, "episode_status", self._on_lot_status, STATUS,
                                 event_callbacks=QUIET_READER)
        for i in range(self.k):
            ns = f"{NAMESPACE}/ego{i}"
            self.create_subscription(EpisodeStatus, f"{ns}/episode_status",
                                     lambda m, i=i: self._on_status(i, m), STATUS, event_callbacks=QUIET_READER)
            self.create_subscription(PlannerDecision, f"{ns}/decision", lambda m, i=i: self._on_decision(i, m), deep,
                                     event_callbacks=QUIET_READER)
            self.create_subscription(DecisionTrace, f"{ns}/avp_planner/debug/decision",
                                     lambda m, i=i: self._on_trace(i, m), deep, event_callbacks=QUIET_READER)
            self.create_subscription(Observation, f"{ns}/observation",
                                     lambda m, info, i=i: self.t_obs[i].setdefault(int(m.step),
                                                                                   int(info["source_timestamp"])),
                                     deep, event_callbacks=QUIET_READER)
            self.create_subscription(PredictedTrajectoryArray, f"{ns}/predictions",
                                     lambda m, info, i=i: self.t_preds[i].setdefault(int(m.step),
                                                                                     int(info["source_timestamp"])),
                                     deep, event_callbacks=QUIET_READER)

    def begin(self, seed: int, reactive: bool) -> None:
        """Forget the last episode; collect the episode (``seed``, ``reactive``)."""
        self.seed, self.reactive = seed, reactive
        self.lot_status = None
        self.status: dict[int, object] = {}
        self.gt: dict[int, object] = {}
        self.braking: dict[int, list[tuple[int, int]]] = {}
        self.decisions: list[dict[int, tuple[bool, int, dict]]] = [{} for _ in range(self.k)]
        self.traces: list[dict[int, tuple]] = [{} for _ in range(self.k)]
        self.t_obs: list[dict[int, int]] = [{} for _ in range(self.k)]
        self.t_preds: list[dict[int, int]] = [{} for _ in range(self.k)]

    def _ours(self, msg) -> bool:
        return int(msg.seed) == self.seed and bool(msg.reactive) == self.reactive

    def _on_gt(self, msg) -> None:
        self.gt[int(msg.step)] = msg

    def _on_braking(self, msg) -> None:
        self.braking[int(msg.step)] = list(zip((int(a) for a in msg.agent_ids), (int(j) for j in msg.ego_indices),
                                               strict=True))

    def _on_lot_status(self, msg) -> None:
        if self._ours(msg):
            self.lot_status = msg

    def _on_status(self, i: int, msg) -> None:
        if self._ours(msg):
            self.status[i] = msg

    def _on_decision(self, i: int, msg) -> None:
        self.decisions[i][int(msg.step)] = (msg.mode == PlannerDecision.MODE_PARK, int(msg.spot_id),
                                            {"spot_selection_time": float(msg.spot_selection_time),
                                             "path_planning_time": float(msg.path_planning_time)})

    def _on_trace(self, i: int, msg) -> None:
        from avp_planner.trace_msg import trace_from_msg

        self.traces[i][int(msg.step)] = (*trace_from_msg(msg), bool(msg.agent_is_pedestrian))

    # ---------------------------------------------------------------- completeness
    @property
    def ended(self) -> bool:
        return (self.lot_status is not None and self.lot_status.state in TERMINAL
                and all(i in self.status and self.status[i].state in TERMINAL for i in range(self.k)))

    def entered(self) -> list[int]:
        """Each ego's entry step (the first ground truth that holds it), -1 if it never entered."""
        out = [-1] * self.k
        for s in sorted(self.gt):
            for a in self.gt[s].agents:
                if a.kind == AgentState.KIND_EGO and int(a.id) < self.k and out[int(a.id)] < 0:
                    out[int(a.id)] = s
        return out

    def driving_steps(self, i: int, entered: int) -> range:
        """The steps ego ``i`` decided: from its entry to its end (its status's ``steps``)."""
        return range(max(entered, 0), int(self.status[i].metrics.steps)) if entered >= 0 else range(0)

    def missing(self) -> dict[str, list[int]]:
        """Steps of the ended episode whose messages have not arrived (ground truth, braking_for, each ego's
        decision and trace)."""
        n = int(self.lot_status.step)
        out = {"ground_truth": [s for s in range(n + 1) if s not in self.gt],
               "braking_for": [s for s in range(n + 1) if s not in self.braking]}
        if not out["ground_truth"]:
            for i, e in enumerate(self.entered()):
                steps = self.driving_steps(i, e)
                out[f"ego{i}/decision"] = [s for s in steps if s not in self.decisions[i]]
                out[f"ego{i}/decision_trace"] = [s for s in steps if s not in self.traces[i]]
        return out

    def publishers_ready(self) -> bool:
        """Every pipeline's decision and trace and the simulator's debug topics are discovered."""
        topics = ["debug/ground_truth", "debug/braking_for"] + [
            f"ego{i}/{t}" for i in range(self.k) for t in ("decision", "avp_planner/debug/decision")]
        return all(self.count_publishers(f"{NAMESPACE}/{t}") >= 1 for t in topics)

    # ---------------------------------------------------------------- records
    def _timings(self, i: int, s: int) -> dict:
        return with_perception(self.decisions[i][s][2], self.t_obs[i].get(s), self.t_preds[i].get(s))

    def records(self, profiles: list, label: str, horizon: float, wall_s: float) -> list[dict]:
        """A record per ego, as :func:`avp_episode.fleet.run_fleet_inproc` writes them."""
        from avp_episode.fleet_metrics import SpotLosses, spot_holders, trace_wait, wait_edges
        from avp_episode.gridlock import GridlockMeter
        from avp_episode.metrics import episode_record
        from avp_motion.trace import DecisionTrace as Trace
        from avp_sim.core.egos import EGO_ID_BASE
        from avp_world.geometry import rect_corners

        n, dt = int(self.lot_status.step), float(self.lot_status.dt)
        entered = self.entered()
        poses: list[dict[int, tuple]] = [{} for _ in range(self.k)]
        holders = []
        for s in range(n + 1):
            veh = [a for a in self.gt[s].agents if a.kind == AgentState.KIND_VEHICLE]
            egos = [a for a in self.gt[s].agents if a.kind == AgentState.KIND_EGO and int(a.id) < self.k]
            for a in egos:
                poses[int(a.id)][s] = (a.pose.x, a.pose.y, a.pose.theta)
            egos.sort(key=lambda a: int(a.id))

            def corners(agents):
                if not agents:
                    return np.zeros((0, 4, 2))
                xy = np.array([[a.pose.x, a.pose.y, a.pose.theta] for a in agents])
                return rect_corners(xy, np.array([a.length for a in agents]), np.array([a.width for a in agents]))

            holders.append(spot_holders(self.lot, corners(veh), corners(egos), [int(a.id) for a in egos]))
        losses, meter = SpotLosses(self.k), GridlockMeter(dt)
        traces = [Trace(dt) for _ in range(self.k)]
        for s in range(n):
            waits = []
            for i in range(self.k):
                if s not in self.decisions[i]:
                    continue
                parking, spot, _ = self.decisions[i][s]
                step, mode, cause, agent, pedestrian = self.traces[i][s]
                traces[i].add_step(step, mode, cause, agent)
                a = trace_wait(bool(cause), agent, pedestrian)
                if a is not None:
                    waits.append((i, a))
                losses.decided(i, parking, spot, holders[s])
            meter.add(s, wait_edges(waits, self.braking.get(s, []), EGO_ID_BASE))
            losses.stepped(holders[s + 1])
        grid = meter.summary(n)
        fleet = ",".join(p.name for p in profiles)
        out = []
        for i in range(self.k):
            st = self.status[i]
            e = entered[i]
            steps = self.driving_steps(i, e)
            ego_poses = np.array([poses[i][s] for s in sorted(poses[i])]).reshape(-1, 3)
            rec = episode_record(method=profiles[i].name, seed=self.seed, reactive=self.reactive,
                                 status=STATE_NAMES.get(int(st.state), str(st.state)),
                                 metrics=status_metrics(st.metrics),
                                 min_ade=np.zeros(0), min_fde=np.zeros(0),
                                 step_timings=[self._timings(i, s) for s in steps], horizon=horizon,
                                 transport="ros", wall_s=wall_s, lot=self.lot_rec, ego_poses=ego_poses,
                                 decision_trace=traces[i].summary())
            rec.update(method=label, ego_method=profiles[i].name, ego=i, egos=self.k, fleet=fleet,
                       episode_s=round(n * dt, 3), entered_s=None if e < 0 else round(e * dt, 3),
                       final_pose=None if e < 0 else [round(float(x), 6) for x in ego_poses[-1]],
                       spots_lost_to_agent=losses.lost[i]["agent"], spots_lost_to_ego=losses.lost[i]["ego"], **grid)
            out.append(rec)
        return out

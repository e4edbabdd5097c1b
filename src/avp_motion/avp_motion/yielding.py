"""Mechanism a (docs/experiment.md) — agents that yield to the ego (``decision.assume_yielding``; off = the paper).

§V-C predicts every car along its intentions and §V-D keeps the ego out of every predicted trajectory. The
reactive agents of §III-B (and of our simulator) do something else: a car stops while the ego is in its way. When
it has stopped, or is braking, with the ego ahead of it, the ego waiting for its moving hypotheses waits for a car
that waits for the ego — the freezing of Trautman & Krause (IROS 2010). This module replaces the hypotheses of such
a car by one: it keeps standing where it is, its footprint grown forward by a braking margin (it may still roll a
little while it stops). A car that moves on is predicted along its intentions again at the next step.
"""

from __future__ import annotations

import math

import numpy as np

from avp_motion.trace import STANDING_SPEED, agent_motion
from avp_world.types import Observation, PredictedTrajectory


def yields_to_ego(obs: Observation, vehicle, lookahead: float) -> bool:
    """``vehicle`` (observed, dynamic) stands or brakes (:func:`~avp_motion.trace.agent_motion`) and the
    ego's centre lies ahead of its front, within ``lookahead`` and within a 60° cone of its heading."""
    if vehicle.is_static or agent_motion(obs, int(vehicle.id), False) not in ("standing", "braking"):
        return False
    x, y, th = (float(a) for a in np.asarray(vehicle.history, float).reshape(-1, 3)[-1])
    dx, dy = float(obs.ego_pose[0]) - x, float(obs.ego_pose[1]) - y
    ahead = dx * math.cos(th) + dy * math.sin(th) - 0.5 * float(vehicle.length)
    dist = math.hypot(dx, dy)
    return 0.0 < ahead <= lookahead and (dx * math.cos(th) + dy * math.sin(th)) >= 0.5 * dist


def yielding_predictions(obs: Observation, predictions: list[PredictedTrajectory], lookahead: float,
                         margin: float, dt: float) -> list[PredictedTrajectory]:
    """``predictions`` with every hypothesis of a car that yields to the ego (:func:`yields_to_ego`) replaced by
    one of probability 1: standing at its pose, ``margin`` longer at the front, for the longest horizon given."""
    yielding = {int(v.id): v for v in obs.vehicles if yields_to_ego(obs, v, lookahead)}
    if not yielding:
        return predictions
    n = max((len(p.poses) for p in predictions), default=1) or 1
    out = [p for p in predictions if p.is_pedestrian or int(p.agent_id) not in yielding]
    for vid, v in yielding.items():
        x, y, th = (float(a) for a in np.asarray(v.history, float).reshape(-1, 3)[-1])
        cx, cy = x + 0.5 * margin * math.cos(th), y + 0.5 * margin * math.sin(th)
        out.append(PredictedTrajectory(agent_id=vid, poses=np.tile([cx, cy, th], (n, 1)), dt=dt, probability=1.0,
                                       length=float(v.length) + margin, width=float(v.width)))
    return out


class ReactionEvidence:
    """Agents seen to stop for the ego (``collision.reactive_evidence``).

    ``collision.reactive_steps`` assumes §III-B's braking rule of every agent. That is a bet: where the agents do
    not react (the non-reactive protocol, a driver who has not seen the ego) the ego drives into their way. Here the
    bet is made only on evidence: an agent seen to stop (to below 0.3 m/s) braking harder than ``decel`` (m/s²:
    harder than a planned stop) while the ego lay ahead of it — within ``lookahead`` m of it and within 60° of the
    direction it moved in — is taken to react for the rest of the episode. The speeds are those between the last two
    observations of it (vehicles: their history; pedestrians: the speed remembered from the step before). A stop to
    a crawl that is not a standstill does not count: the simulator's manoeuvres slow from 1.1 m/s to 0.5 m/s
    within one step.
    """

    def __init__(self, lookahead: float, decel: float):
        self.lookahead, self.decel = float(lookahead), float(decel)
        self.reset()

    def reset(self) -> None:
        """Forget every agent (a new episode)."""
        self.seen: set[tuple[bool, int]] = set()
        self._ped_vel: dict[int, tuple[int, np.ndarray]] = {}  # id -> (step, velocity) at its last observation

    def _stopped_for_ego(self, obs: Observation, pos: np.ndarray, v_before: np.ndarray, v_now: np.ndarray) -> bool:
        s_before, s_now = float(np.hypot(*v_before)), float(np.hypot(*v_now))
        if s_now >= STANDING_SPEED or s_before - s_now < self.decel * obs.dt:
            return False
        d = np.asarray(obs.ego_pose[:2], dtype=float) - pos
        dist = float(np.hypot(*d))
        ahead = float(np.dot(d, v_before)) / s_before
        return 0.0 < dist <= self.lookahead and ahead >= 0.5 * dist

    def update(self, obs: Observation) -> set[tuple[bool, int]]:
        """Add the agents of ``obs`` that stop for the ego now; the keys (is a pedestrian, id) of all seen so far."""
        for v in obs.vehicles:
            h = np.asarray(v.history, dtype=float).reshape(-1, 3)
            if v.is_static or len(h) < 3 or (False, int(v.id)) in self.seen:
                continue
            v_before, v_now = (h[-2, :2] - h[-3, :2]) / obs.dt, (h[-1, :2] - h[-2, :2]) / obs.dt
            if self._stopped_for_ego(obs, h[-1, :2], v_before, v_now):
                self.seen.add((False, int(v.id)))
        vel = {}
        for p in obs.pedestrians:
            pos = np.asarray(p.position, dtype=float)
            vel[int(p.id)] = (pos - np.asarray(p.previous_position, dtype=float)) / obs.dt
            last = self._ped_vel.get(int(p.id))
            fresh = last is not None and last[0] == obs.step - 1
            if fresh and self._stopped_for_ego(obs, pos, last[1], vel[int(p.id)]):
                self.seen.add((True, int(p.id)))
        self._ped_vel = {i: (obs.step, w) for i, w in vel.items()}
        return self.seen

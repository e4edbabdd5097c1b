"""Rewrites of the predicted trajectories the planner checks against (§V-D-1 reads every hypothesis of every agent):
the switches ``collision.hypotheses: most_likely``, ``collision.receding: straight`` and ``collision.reactive_model:
hold`` (docs/parameters.md), each a departure from the paper named there. Pure functions of the predictions and
the observation; used by the planner's inputs (:mod:`avp_motion.planner_inputs`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from avp_world.types import Observation, PredictedTrajectory


def most_likely(preds: list[PredictedTrajectory]) -> list[PredictedTrajectory]:
    """``collision.hypotheses: most_likely``: of each agent's predicted trajectories only the most probable (the
    first of equals), in the order the agents came."""
    best: dict[tuple[bool, int], PredictedTrajectory] = {}
    for p in preds:
        key = (bool(p.is_pedestrian), int(p.agent_id))
        if key not in best or float(p.probability) > float(best[key].probability):
            best[key] = p
    return list(best.values())


def _set_aside(preds: list[PredictedTrajectory], chosen) -> tuple[list[PredictedTrajectory], dict]:
    """The predictions of the agents not ``chosen(key)`` (key: (is a pedestrian, id)), and for each chosen agent that
    has predictions: (its first prediction, the longest horizon among them), in the order the agents came."""
    kept, set_aside = [], {}
    for p in preds:
        key = (bool(p.is_pedestrian), int(p.agent_id))
        if chosen(key):
            first, n = set_aside.get(key, (p, 0))
            set_aside[key] = (first, max(n, len(p.poses)))
        else:
            kept.append(p)
    return kept, set_aside


def receding_straight(preds: list[PredictedTrajectory], obs: Observation, dt: float,
                      still_speed: float) -> list[PredictedTrajectory]:
    """``collision.receding: straight``: the predicted trajectories of every observed dynamic car that drives away from
    the ego (faster than ``still_speed`` m/s, its last displacement pointing away from the ego) are replaced by one,
    probability 1: straight on at that displacement per step with its heading (§VI-B-1's constant velocity), as many
    steps as its longest hypothesis. The other agents' are kept as given."""
    ego = np.asarray(obs.ego_pose[:2], dtype=float)
    receding = {}
    for v in obs.vehicles:
        h = np.asarray(v.history, dtype=float).reshape(-1, 3)
        if v.is_static or len(h) < 2:
            continue
        d = h[-1, :2] - h[-2, :2]
        if np.hypot(*d) / obs.dt >= still_speed and float(np.dot(d, ego - h[-1, :2])) < 0.0:
            receding[(False, int(v.id))] = (v, h[-1], d * (dt / obs.dt))
    if not receding:
        return preds
    out, set_aside = _set_aside(preds, receding.__contains__)
    for key, (_, steps) in set_aside.items():
        v, cur, step = receding[key]
        k = np.arange(1, steps + 1)[:, None]
        poses = np.column_stack([cur[:2] + k * step, np.full(steps, cur[2])])
        out.append(PredictedTrajectory(agent_id=key[1], poses=poses, dt=dt, length=float(v.length),
                                       width=float(v.width)))
    return out


def held_where_they_are(preds: list[PredictedTrajectory], obs: Observation,
                        keys: frozenset | None) -> list[PredictedTrajectory]:
    """``collision.reactive_model: hold``: each agent the reaction applies to (``keys``; None = every one) is predicted
    by one trajectory standing at its observed pose, as `blind` predicts every agent; the others keep theirs."""
    now = {(False, int(v.id)): np.asarray(v.history, dtype=float).reshape(-1, 3)[-1] for v in obs.vehicles}
    now.update({(True, int(p.id)): np.array([*np.asarray(p.position, dtype=float), 0.0]) for p in obs.pedestrians})
    out, set_aside = _set_aside(preds, lambda key: key in now and (keys is None or key in keys))
    for key, (first, n) in set_aside.items():
        out.append(replace(first, poses=np.tile(now[key], (n, 1)), probability=1.0))
    return out

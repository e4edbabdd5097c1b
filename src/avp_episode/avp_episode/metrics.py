"""§VI-B metrics of one episode and their aggregates over episodes (Table I), ROS-free.

Per episode (one JSON line, :func:`episode_record`):

* success, collision, spot stolen, interrupted timesteps, parking time — the simulator's
  :class:`~avp_sim.core.metrics.EpisodeMetrics` (docs/metrics.md);
* minADE / minFDE (:func:`prediction_errors`): at every step t and for every observed dynamic vehicle with
  predicted trajectories (all its modes, what the planner received), against that vehicle's ground-truth
  future from the simulator's log over the horizon H (default 4 s = t_pred of the predictors; the paper does
  not state it):

      ADE_m = 1/H_n sum_{j=1..H_n} |p^m_{t+j dt} - p_{t+j dt}|,   FDE_m = |p^m_{t+H} - p_{t+H}|,
      minADE = min_m ADE_m,   minFDE = min_m FDE_m   (each minimised on its own, Argoverse's definition),

  counted only where the log covers t + H (episodes end at parking); the episode's value is the mean over
  its (t, vehicle) samples (NaN when there is none);
* spot-selection time: mean over the episode's steps; path-planning time: mean over the steps that ran a
  Hybrid A* search (``path_planning_time > 0``; the mean over all steps is kept too).

Aggregates (:func:`aggregate`): rates in % with a 95 % Wilson score interval; everything else mean ± std
(population std) over the episodes that have a value (parking time: successful episodes only).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence

import numpy as np

from avp_world.types import PredictedTrajectory

TIMING_KEYS = ("spot_selection_time", "path_planning_time", "perception_time")
Z95 = 1.959963984540054


def prediction_errors(predictions: Mapping[int, Sequence[PredictedTrajectory]], gt_vehicles: np.ndarray,
                      vehicle_ids: np.ndarray, dt: float, horizon: float) -> tuple[np.ndarray, np.ndarray]:
    """(minADE, minFDE) samples, one per (step, predicted vehicle) whose ground-truth future covers ``horizon``.

    Args:
        predictions: step k -> the trajectories predicted at t_k (pedestrians are skipped).
        gt_vehicles: (K + 1, N, 3) ground-truth vehicle states at steps 0..K (the simulator's log).
        vehicle_ids: (N,) ids of the columns of ``gt_vehicles``.
        dt: the simulator's step.
        horizon: H [s].
    """
    gt = np.asarray(gt_vehicles, dtype=float)
    n_h = int(round(horizon / dt))
    if n_h < 1:
        raise ValueError(f"horizon must be at least one step ({dt} s), got {horizon}")
    col = {int(v): j for j, v in enumerate(np.asarray(vehicle_ids).tolist())}
    t_eval = dt * np.arange(1, n_h + 1)
    ades, fdes = [], []
    for k in sorted(predictions):
        if k + n_h > len(gt) - 1:
            continue
        by_agent: dict[int, list[np.ndarray]] = {}
        for p in predictions[k]:
            if p.is_pedestrian or int(p.agent_id) not in col:
                continue
            poses = np.asarray(p.poses, dtype=float).reshape(-1, 3)
            if len(poses) == 0 or p.dt * len(poses) < horizon - 1e-9:
                continue
            t_src = p.dt * np.arange(1, len(poses) + 1)
            xy = np.column_stack([np.interp(t_eval, t_src, poses[:, 0]), np.interp(t_eval, t_src, poses[:, 1])])
            by_agent.setdefault(int(p.agent_id), []).append(xy)
        for aid, modes in by_agent.items():
            truth = gt[k + 1: k + n_h + 1, col[aid], :2]  # (H, 2)
            err = np.linalg.norm(np.stack(modes) - truth[None], axis=2)  # (M, H)
            ades.append(float(err.mean(axis=1).min()))
            fdes.append(float(err[:, -1].min()))
    return np.asarray(ades), np.asarray(fdes)


def _mean(x: Iterable[float]) -> float | None:
    a = np.asarray(list(x), dtype=float)
    return float(a.mean()) if a.size else None


def episode_record(*, method: str, seed: int, reactive: bool, status: str, metrics: Mapping, min_ade: np.ndarray,
                   min_fde: np.ndarray, step_timings: Sequence[Mapping], horizon: float, transport: str,
                   wall_s: float, lot: Mapping | None = None, ego_poses: np.ndarray | None = None,
                   decision_trace: Mapping | None = None) -> dict:
    """One JSON line: identity (with the lot, :func:`lot_record`), the §VI-B metrics, the ego's reversals and
    U-turns (:func:`motion_counts` of ``ego_poses``, its pose per step), and (under ``timings``) what depends on
    compute speed. ``decision_trace``: the planner's per-episode trace summary (steps per mode, idle steps per
    cause, the longest idle spells; :class:`avp_motion.trace.DecisionTrace`)."""
    pt = metrics.get("parking_time")
    pt = None if pt is None or (isinstance(pt, float) and math.isnan(pt)) else float(pt)
    sel = [float(t["spot_selection_time"]) for t in step_timings]
    plan = [float(t["path_planning_time"]) for t in step_timings]
    searched = [p for p in plan if p > 0.0]
    return {
        "method": method, "seed": int(seed), "mode": "reactive" if reactive else "non_reactive",
        "status": status, "success": bool(metrics["success"]), "collision": bool(metrics["collision"]),
        "collision_with": str(metrics.get("collision_with", "")),
        "collision_at_fault": bool(metrics.get("collision_at_fault", False)),
        "spot_stolen": bool(metrics["spot_stolen"]),
        "parked_spot_id": int(metrics["parked_spot_id"]), "interrupted_steps": int(metrics["interrupted_steps"]),
        "interrupted_agent_steps": int(metrics["interrupted_agent_steps"]), "parking_time": pt,
        "steps": int(metrics["steps"]),
        "min_ade": _mean(min_ade), "min_fde": _mean(min_fde), "ade_samples": int(len(min_ade)),
        "ade_horizon": float(horizon),
        "lot": dict(lot) if lot is not None else None,
        **(motion_counts(ego_poses) if ego_poses is not None else {}),
        **({"decision_trace": dict(decision_trace)} if decision_trace is not None else {}),
        "transport": transport,
        "timings": {
            "spot_selection_time": _mean(sel), "path_planning_time": _mean(searched),
            "path_planning_time_all_steps": _mean(plan), "planning_steps": len(searched), "decisions": len(plan),
            "perception_time": _mean(float(t.get("perception_time", 0.0)) for t in step_timings),
            "wall_s": round(float(wall_s), 3),
        },
    }


U_TURN_DEG = 150.0  # the ego's heading turned this far from its reference: it turned round
MOVING = 0.01  # m per step: slower is standing (no travel direction)


def motion_counts(ego_poses: np.ndarray) -> dict:
    """Direction reversals and U-turns of the ego over an episode, from its poses (N, 3) per step.

    ``reversals``: changes of gear between consecutive moving steps (forward <-> backward, the sign of the step's
    displacement along the heading; steps moving less than ``MOVING`` m are skipped). ``u_turns``: how often the
    heading turned at least ``U_TURN_DEG`` degrees from its reference, which is the start heading and, after each
    U-turn, the heading then (a three-point turn or a loop round a block: one each; parking 90 degrees into a spot:
    none)."""
    p = np.asarray(ego_poses, dtype=float).reshape(-1, 3)
    reversals, u_turns, gear, ref = 0, 0, 0, (float(p[0, 2]) if len(p) else 0.0)
    for k in range(len(p) - 1):
        d = p[k + 1, :2] - p[k, :2]
        if float(np.hypot(*d)) >= MOVING:
            g = 1 if float(d @ (math.cos(p[k, 2]), math.sin(p[k, 2]))) >= 0 else -1
            reversals += int(gear != 0 and g != gear)
            gear = g
        turned = abs(math.remainder(float(p[k + 1, 2]) - ref, 2 * math.pi))
        if turned >= math.radians(U_TURN_DEG):
            u_turns += 1
            ref = float(p[k + 1, 2])
    return {"reversals": reversals, "u_turns": u_turns}


def lot_record(lot) -> dict:
    """How a record names its lot: the lot's name and the SHA-256 of the file it was loaded from."""
    return {"name": lot.name, "sha256": lot.sha256}


def comparable(record: Mapping) -> dict:
    """A record without what depends on compute speed or transport (for determinism checks)."""
    return {k: v for k, v in record.items() if k not in ("timings", "transport")}


# ------------------------------------------------------------------------------------------ aggregates


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """95 % Wilson score interval of a proportion k / n, in [0, 1] ((nan, nan) for n = 0)."""
    if n == 0:
        return math.nan, math.nan
    p = k / n
    den = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return max(0.0, centre - half), min(1.0, centre + half)


def mean_std(values: Iterable[float | None]) -> dict:
    a = np.asarray([v for v in values if v is not None and not (isinstance(v, float) and math.isnan(v))],
                   dtype=float)
    if a.size == 0:
        return {"mean": None, "std": None, "n": 0}
    return {"mean": float(a.mean()), "std": float(a.std()), "n": int(a.size)}


def rate(flags: Sequence[bool]) -> dict:
    n, k = len(flags), int(sum(bool(f) for f in flags))
    lo, hi = wilson(k, n)
    return {"percent": 100.0 * k / n if n else None, "k": k, "n": n,
            "ci95": [100.0 * lo, 100.0 * hi] if n else None}


def aggregate(records: Iterable[Mapping]) -> dict[tuple[str, str], dict]:
    """(method, mode) -> Table I statistics of those episodes."""
    groups: dict[tuple[str, str], list[Mapping]] = {}
    for r in records:
        groups.setdefault((r["method"], r["mode"]), []).append(r)
    out = {}
    for key, rs in groups.items():
        t = [r.get("timings", {}) for r in rs]
        out[key] = {
            "episodes": len(rs),
            "success": rate([r["success"] for r in rs]),
            "collision": rate([r["collision"] for r in rs]),
            "spot_stolen": rate([r["spot_stolen"] for r in rs]),
            "interrupted_steps": mean_std(r["interrupted_steps"] for r in rs),
            "spot_selection_time": mean_std(x.get("spot_selection_time") for x in t),
            "path_planning_time": mean_std(x.get("path_planning_time") for x in t),
            "parking_time": mean_std(r["parking_time"] for r in rs if r["success"]),
            "min_ade": mean_std(r["min_ade"] for r in rs),
            "min_fde": mean_std(r["min_fde"] for r in rs),
            "wall_s": mean_std(x.get("wall_s") for x in t),
        }
    return out

"""Trajectory prediction of observed agents (paper §V-C), chosen by name: ``make_predictor(name, lot)``.

Every predictor has ``predict(obs, intentions=(), horizon=None) -> list[PredictedTrajectory]``;
``poses[j]`` is the predicted state at t + (j + 1) dt for j < round(horizon / dt).

* ``"bezier"`` (:class:`BezierPredictor`, the paper's method): for every observed dynamic vehicle V_k and
  every intention with probability >= mu (0.3, §VI-A) — spots with eta_k,i >= mu, exploration points with
  eta_hat_k,q >= mu — a cubic Bezier curve with control points (eqs. 9-12)

      P0 = p_k,   P3 = p_goal,
      P1 = p_k + zeta v_hat [cos(phi), sin(phi)],
      P2 = p_goal + zeta v_hat [cos(theta_goal + pi), sin(theta_goal + pi)],

  zeta = 3 s, followed at the constant speed v_hat (arc-length parameterised, so consecutive positions are
  v_hat dt apart) for up to t_pred; after t_pred, or once the curve ends, the vehicle keeps going at v_hat
  along the curve's tangent (the constant-velocity fill of §V-C). The goal is the spot centre and heading,
  or the exploration point (the paper writes p_S_i in eq. 12 for both; p_goal is meant).
  phi: eq. (11) literally uses theta_k + pi, i.e. P1 *behind* the vehicle, so the curve would start in
  reverse. That is right for a vehicle that is reversing (e.g. backing into a spot), wrong for one driving
  forward; ``start_tangent="motion"`` (default) uses the direction of the last displacement — theta_k + pi
  when reversing (the paper's case), theta_k when driving forward; ``"paper"`` is eq. (11) as printed and
  ``"heading"`` always theta_k. Predicted headings are the curve tangent (+ pi for a reversing vehicle
  with ``"motion"``).
  A vehicle with no intention >= mu, or none at all, is predicted at constant velocity (probability 1);
  so is the "none" mass >= mu when there is no exploration point to condition on.
* ``"constant_velocity"`` (:class:`ConstantVelocityPredictor`): every dynamic vehicle keeps its last
  displacement per step (p_t - p_t-dt) and its heading.
* ``"hybrid_astar"`` (:class:`~avp_predictors.prediction_astar.HybridAStarPredictor`): for
  every intention >= mu a path from the vehicle to the goal planned with the ego planner's Hybrid A*
  (§V-D), followed at v_hat; constant velocity when no path is found (see that module).
* ``"learned"`` (:class:`~avp_predictors.learned_prediction.LearnedPredictor`): ParkPredict+'s
  trajectory transformer conditioned on the same goals as the Bezier curves (§VI-B-1 "Learned Model").

Pedestrians are always predicted at constant velocity from their two positions, v_hat = |p_t - p_t-dt| / dt
(§V-C), with theta = 0.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from avp_predictors.intention import Intention
from avp_world import plugins
from avp_world.geometry import wrap_angle
from avp_world.lot import LotMap
from avp_world.types import Observation, ObservedPedestrian, ObservedVehicle, PredictedTrajectory

START_TANGENTS = ("motion", "paper", "heading")


@dataclass(frozen=True)
class HybridAStarPredictionSettings:
    """The ``"hybrid_astar"`` predictor (:mod:`.prediction_astar`): search caps and the followed speed."""

    max_iterations: int = 200  # node pops per Hybrid A* query (the ego planner's search, §V-D)
    time_cap: float = 1.0  # s per query, wall clock: a safety net only (the iteration cap ends searches first)
    max_length: float = 40.0  # m: a longer path counts as no plan (constant velocity instead)
    min_speed: float = 0.0  # m/s: the path is followed at max(v_hat, min_speed)
    footprint_margin: float = 0.1  # m: clearance the searched path keeps to spots and static vehicles

    def validate(self) -> HybridAStarPredictionSettings:
        if int(self.max_iterations) != self.max_iterations or self.max_iterations < 1:
            raise ValueError(f"hybrid_astar.max_iterations must be an integer >= 1, got {self.max_iterations!r}")
        for name in ("time_cap", "max_length"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"hybrid_astar.{name} must be a finite number > 0, got {v!r}")
        for name in ("min_speed", "footprint_margin"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"hybrid_astar.{name} must be a finite number >= 0, got {v!r}")
        return self


@dataclass(frozen=True)
class LearnedPredictionSettings:
    """The ``"learned"`` predictor (:mod:`.learned_prediction`): weights and inference settings."""

    weights: str = ""  # trajectory transformer file or a name in models/; empty: the shipped one, else random
    seed: int = 0  # seed of the random weights (used only without a weights file)
    threads: int = 1  # torch.set_num_threads at start-up (1: deterministic and fastest on a shared CPU)
    t_hist: float = 4.0  # s of ego poses kept for the ego's trail in the BEVs (as the belief node's t_hist)

    def validate(self) -> LearnedPredictionSettings:
        if int(self.seed) != self.seed or self.seed < 0:
            raise ValueError(f"learned.seed must be an integer >= 0, got {self.seed!r}")
        if int(self.threads) != self.threads or self.threads < 1:
            raise ValueError(f"learned.threads must be an integer >= 1, got {self.threads!r}")
        if not (math.isfinite(self.t_hist) and self.t_hist >= 0):
            raise ValueError(f"learned.t_hist must be a finite number >= 0, got {self.t_hist!r}")
        return self


@dataclass(frozen=True)
class PredictionConfig:
    """Parameters of §V-C (defaults: §VI-A where the paper gives them)."""

    zeta: float = 3.0  # s, distance of the inner control points in units of v_hat (§VI-A)
    mu: float = 0.3  # intention threshold (§VI-A)
    t_pred: float = 4.0  # s along the Bezier curve (not given in the paper; ParkPredict+'s 4 s horizon)
    horizon: float | None = None  # s predicted in total, max(t_pred, t_plan); None: t_pred
    start_tangent: str = "motion"  # "motion", "paper" (eq. 11 as printed) or "heading"
    samples: int = 128  # points of the arc-length table of each curve
    hybrid_astar: HybridAStarPredictionSettings = field(default_factory=HybridAStarPredictionSettings)
    learned: LearnedPredictionSettings = field(default_factory=LearnedPredictionSettings)

    def validate(self) -> PredictionConfig:
        for name in ("zeta", "t_pred"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
        if not 0.0 <= self.mu <= 1.0:
            raise ValueError(f"mu must be in [0, 1], got {self.mu!r}")
        if self.horizon is not None and not (math.isfinite(self.horizon) and self.horizon >= 0):
            raise ValueError(f"horizon must be None or a finite number >= 0, got {self.horizon!r}")
        if self.start_tangent not in START_TANGENTS:
            raise ValueError(f"start_tangent must be one of {START_TANGENTS}, got {self.start_tangent!r}")
        if self.samples < 4:
            raise ValueError(f"samples must be >= 4, got {self.samples!r}")
        self.hybrid_astar.validate()
        self.learned.validate()
        return self


class TrajectoryPredictor(Protocol):
    name: str

    def predict(self, obs: Observation, intentions: Iterable[Intention] = (),
                horizon: float | None = None) -> list[PredictedTrajectory]: ...


# ------------------------------------------------------------------------------------------- helpers


def last_displacement(history: np.ndarray) -> np.ndarray:
    """p_t - p_t-dt from a (H, 3) history (zeros with a single pose)."""
    h = np.asarray(history, dtype=float).reshape(-1, 3)
    return h[-1, :2] - h[-2, :2] if len(h) >= 2 else np.zeros(2)


def vehicle_motion(history: np.ndarray, dt: float) -> tuple[float, bool]:
    """(v_hat, reversing): v_hat = |p_t - p_t-dt| / dt; reversing iff the displacement points against the heading."""
    d = last_displacement(history)
    speed = float(math.hypot(d[0], d[1]) / dt) if dt > 0 else 0.0
    th = float(np.asarray(history, dtype=float).reshape(-1, 3)[-1, 2])
    return speed, bool(speed > 0 and d[0] * math.cos(th) + d[1] * math.sin(th) < 0)


def bezier_control_points(pose: np.ndarray, speed: float, goal: np.ndarray, zeta: float,
                          start_angle: float | None = None) -> np.ndarray:
    """Eqs. (9)-(12): (4, 2) control points from the vehicle pose (x, y, theta), v_hat and the goal (x, y, theta).

    ``start_angle`` is the direction phi of P1 from P0; None means eq. (11) as printed, theta + pi.
    """
    p = np.asarray(pose, dtype=float)
    g = np.asarray(goal, dtype=float)
    phi = p[2] + math.pi if start_angle is None else float(start_angle)
    r = zeta * speed
    return np.array([
        p[:2],  # eq. (9)
        p[:2] + r * np.array([math.cos(phi), math.sin(phi)]),  # eq. (11)
        g[:2] + r * np.array([math.cos(g[2] + math.pi), math.sin(g[2] + math.pi)]),  # eq. (12)
        g[:2],  # eq. (10)
    ])


def bezier_point(ctrl: np.ndarray, u: np.ndarray) -> np.ndarray:
    """B(u) = (1-u)^3 P0 + 3(1-u)^2 u P1 + 3(1-u) u^2 P2 + u^3 P3 for (M,) parameters -> (M, 2)."""
    u = np.asarray(u, dtype=float)[:, None]
    w = 1.0 - u
    return w**3 * ctrl[0] + 3 * w**2 * u * ctrl[1] + 3 * w * u**2 * ctrl[2] + u**3 * ctrl[3]


def bezier_derivative(ctrl: np.ndarray, u: np.ndarray) -> np.ndarray:
    """B'(u) = 3(1-u)^2 (P1-P0) + 6(1-u)u (P2-P1) + 3u^2 (P3-P2) -> (M, 2)."""
    u = np.asarray(u, dtype=float)[:, None]
    w = 1.0 - u
    return 3 * w**2 * (ctrl[1] - ctrl[0]) + 6 * w * u * (ctrl[2] - ctrl[1]) + 3 * u**2 * (ctrl[3] - ctrl[2])


def follow_bezier(ctrl: np.ndarray, speed: float, dt: float, n_steps: int, n_curve: int, heading0: float,
                  reversing: bool = False, samples: int = 128) -> np.ndarray:
    """Poses (n_steps, 3) at t + dt ... travelling at constant ``speed`` along the curve (arc length s_j =
    speed * j * dt) for at most ``n_curve`` steps, then straight on along the tangent at the same speed.

    Headings are the tangent angle (+ pi when ``reversing``); ``heading0`` is used where the tangent vanishes.
    """
    out = np.empty((n_steps, 3))
    if n_steps == 0:
        return out
    s = speed * dt * np.arange(1, n_steps + 1)
    if speed <= 0.0:
        out[:] = (ctrl[0, 0], ctrl[0, 1], heading0)
        return out
    # arc-length table: dense parameter samples, cumulative chord length
    u_tab = np.linspace(0.0, 1.0, samples)
    pts = bezier_point(ctrl, u_tab)
    s_tab = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    length = s_tab[-1]
    s_anchor = min(length, speed * dt * n_curve)  # where the curve phase stops
    on_curve = s <= s_anchor + 1e-12
    u_anchor = float(np.interp(s_anchor, s_tab, u_tab))
    u = np.interp(np.append(s[on_curve], s_anchor), s_tab, u_tab)
    u[-1] = u_anchor
    pos = bezier_point(ctrl, u)
    tan = bezier_derivative(ctrl, u)
    norm = np.hypot(tan[:, 0], tan[:, 1])
    flip = math.pi if reversing else 0.0
    heading = np.where(norm > 1e-9, np.arctan2(tan[:, 1], tan[:, 0]) + flip, heading0)
    n_on = int(on_curve.sum())
    out[:n_on, :2] = pos[:n_on]
    out[:n_on, 2] = heading[:n_on]
    if n_on < n_steps:  # constant velocity along the tangent at the anchor
        direction = tan[-1] / norm[-1] if norm[-1] > 1e-9 else (
            np.array([math.cos(heading0), math.sin(heading0)]) * (-1.0 if reversing else 1.0))
        rest = s[n_on:] - s_anchor
        out[n_on:, :2] = pos[-1] + rest[:, None] * direction
        out[n_on:, 2] = heading[-1]
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def intention_trajectory(vehicle: ObservedVehicle, poses: np.ndarray, dt: float, probability: float, spot_id: int,
                         goal: np.ndarray) -> PredictedTrajectory:
    """The prediction of ``vehicle`` for one intention (a spot ``spot_id`` >= 0 or an exploration point, -1)."""
    return PredictedTrajectory(agent_id=int(vehicle.id), poses=poses, dt=dt, probability=probability,
                               length=float(vehicle.length), width=float(vehicle.width), spot_id=int(spot_id),
                               goal=np.asarray(goal, dtype=float).copy())


def complete_predictions(out: list[PredictedTrajectory], vehicle: ObservedVehicle, intention: Intention, dt: float,
                         n_steps: int, mu: float) -> list[PredictedTrajectory]:
    """What the intentions leave to constant velocity (§V-C): the "none" mass >= mu when there is no exploration
    point to condition it on, and a vehicle with no intention >= mu at all. Appends to ``out`` and returns it."""
    if intention.none_probability >= mu and len(intention.exploration_points) == 0:
        out.append(constant_velocity_vehicle(vehicle, dt, n_steps, intention.none_probability))
    if not out:
        out.append(constant_velocity_vehicle(vehicle, dt, n_steps))
    return out


def constant_velocity_vehicle(vehicle: ObservedVehicle, dt: float, n_steps: int,
                              probability: float = 1.0) -> PredictedTrajectory:
    """Constant velocity: p_t + j (p_t - p_t-dt), heading kept."""
    d = last_displacement(vehicle.history)
    j = np.arange(1, n_steps + 1)[:, None]
    poses = np.empty((n_steps, 3))
    poses[:, :2] = np.asarray(vehicle.pose[:2], dtype=float) + j * d
    poses[:, 2] = vehicle.pose[2]
    return PredictedTrajectory(agent_id=int(vehicle.id), poses=poses, dt=dt, probability=float(probability),
                               length=float(vehicle.length), width=float(vehicle.width))


def constant_velocity_pedestrian(ped: ObservedPedestrian, dt: float, n_steps: int) -> PredictedTrajectory:
    """§V-C: pedestrians at constant velocity v_hat = |p_t - p_t-dt| / dt from their two positions (theta = 0)."""
    p = np.asarray(ped.position, dtype=float)
    d = p - np.asarray(ped.previous_position, dtype=float)
    j = np.arange(1, n_steps + 1)[:, None]
    poses = np.zeros((n_steps, 3))
    poses[:, :2] = p + j * d
    return PredictedTrajectory(agent_id=int(ped.id), poses=poses, dt=dt, probability=1.0, is_pedestrian=True,
                               radius=float(ped.radius))


def _n_steps(seconds: float, dt: float) -> int:
    return int(round(seconds / dt)) if dt > 0 else 0


# ----------------------------------------------------------------------------------------- predictors


class ConstantVelocityPredictor:
    """Every observed dynamic vehicle and pedestrian at constant velocity (intentions are ignored)."""

    name = "constant_velocity"

    def __init__(self, lot: LotMap | None = None, config: PredictionConfig = PredictionConfig()):
        self.lot = lot
        self.config = config.validate()

    def horizon(self, horizon: float | None) -> float:
        if horizon is not None:
            return float(horizon)
        return self.config.horizon if self.config.horizon is not None else self.config.t_pred

    def predict(self, obs: Observation, intentions: Iterable[Intention] = (),
                horizon: float | None = None) -> list[PredictedTrajectory]:
        n = _n_steps(self.horizon(horizon), obs.dt)
        out = [constant_velocity_vehicle(v, obs.dt, n) for v in obs.vehicles if not v.is_static]
        out += [constant_velocity_pedestrian(p, obs.dt, n) for p in obs.pedestrians]
        return out


class BezierPredictor(ConstantVelocityPredictor):
    """Intention-conditioned cubic Bezier prediction of §V-C (see the module docstring)."""

    name = "bezier"

    def __init__(self, lot: LotMap, config: PredictionConfig = PredictionConfig()):
        super().__init__(lot, config)
        if lot is None:
            raise ValueError("the Bezier predictor needs the lot (spot poses are the goals)")

    def start_angle(self, pose: np.ndarray, reversing: bool) -> float:
        mode = self.config.start_tangent
        if mode == "paper" or (mode == "motion" and reversing):
            return float(pose[2]) + math.pi
        return float(pose[2])

    def goals(self, intention: Intention) -> list[tuple[np.ndarray, float, int]]:
        """(goal pose, probability, spot id or -1) of every intention >= mu."""
        mu = self.config.mu
        out = []
        for sid, p in zip(intention.spot_ids, intention.spot_probabilities, strict=True):
            if p >= mu:
                out.append((self.lot.spot_poses[self.lot.spot_index(int(sid))], float(p), int(sid)))
        for pt, p in zip(intention.exploration_points, intention.exploration_probabilities, strict=True):
            if p >= mu:
                out.append((np.asarray(pt, dtype=float), float(p), -1))
        return out

    def predict_vehicle(self, vehicle: ObservedVehicle, intention: Intention | None, dt: float,
                        n_steps: int) -> list[PredictedTrajectory]:
        cfg = self.config
        if intention is None:
            return [constant_velocity_vehicle(vehicle, dt, n_steps)]
        pose = np.asarray(vehicle.pose, dtype=float)
        speed, reversing = vehicle_motion(vehicle.history, dt)
        phi = self.start_angle(pose, reversing)
        flip = reversing and cfg.start_tangent == "motion"  # a reversing car points against its motion
        n_curve = min(n_steps, _n_steps(cfg.t_pred, dt))
        out = []
        for goal, p, sid in self.goals(intention):
            ctrl = bezier_control_points(pose, speed, goal, cfg.zeta, phi)
            poses = follow_bezier(ctrl, speed, dt, n_steps, n_curve, float(pose[2]), flip, cfg.samples)
            out.append(intention_trajectory(vehicle, poses, dt, p, sid, goal))
        return complete_predictions(out, vehicle, intention, dt, n_steps, cfg.mu)

    def predict(self, obs: Observation, intentions: Iterable[Intention] = (),
                horizon: float | None = None) -> list[PredictedTrajectory]:
        n = _n_steps(self.horizon(horizon), obs.dt)
        by_id = {int(it.vehicle_id): it for it in intentions}
        out: list[PredictedTrajectory] = []
        for v in obs.vehicles:
            if not v.is_static:
                out += self.predict_vehicle(v, by_id.get(int(v.id)), obs.dt, n)
        out += [constant_velocity_pedestrian(p, obs.dt, n) for p in obs.pedestrians]
        return out


class StaticPredictor(ConstantVelocityPredictor):
    """Every observed dynamic vehicle and pedestrian stays where it is (intentions ignored): the ``blind``
    reference method of docs/experiment.md, which sees other agents as obstacles at their current pose only."""

    name = "static"

    def predict(self, obs: Observation, intentions: Iterable[Intention] = (),
                horizon: float | None = None) -> list[PredictedTrajectory]:
        n = _n_steps(self.horizon(horizon), obs.dt)
        out = [PredictedTrajectory(agent_id=int(v.id), poses=np.repeat(np.asarray(v.pose, float)[None], n, 0),
                                   dt=obs.dt, length=float(v.length), width=float(v.width))
               for v in obs.vehicles if not v.is_static]
        for q in obs.pedestrians:
            poses = np.zeros((n, 3))
            poses[:, :2] = np.asarray(q.position, dtype=float)
            out.append(PredictedTrajectory(agent_id=int(q.id), poses=poses, dt=obs.dt, is_pedestrian=True,
                                           radius=float(q.radius)))
        return out


#: The built-in predictors, as "module:attribute" (imported on demand: ``hybrid_astar`` pulls in the planner core,
#: ``learned`` torch). More come from installed packages through the entry-point group :data:`ENTRY_POINT_GROUP`.
BUILTIN_PREDICTORS = {
    "bezier": "avp_predictors.prediction:BezierPredictor",
    "constant_velocity": "avp_predictors.prediction:ConstantVelocityPredictor",
    "hybrid_astar": "avp_predictors.prediction_astar:HybridAStarPredictor",
    "learned": "avp_predictors.learned_prediction:LearnedPredictor",
    "static": "avp_predictors.prediction:StaticPredictor",
}
PREDICTOR_NAMES = tuple(BUILTIN_PREDICTORS)
#: Python entry-point group of predictor plugins: ``name = "package.module:Class"``, where ``Class(lot, config)``
#: returns an object with ``predict(obs, intentions) -> list[PredictedTrajectory]`` (docs/custom_predictor.md)
ENTRY_POINT_GROUP = "avp.predictors"


def available_predictors() -> dict[str, str]:
    """Every predictor this installation can make: the built-ins, then the plugins (a plugin cannot replace a
    built-in name)."""
    return plugins.available(ENTRY_POINT_GROUP, BUILTIN_PREDICTORS)


def make_predictor(name: str, lot: LotMap | None = None, config: PredictionConfig = PredictionConfig()
                   ) -> TrajectoryPredictor:
    """The predictor called ``name`` (a built-in or an ``avp.predictors`` plugin); ValueError lists the names."""
    cls = plugins.load_class(ENTRY_POINT_GROUP, BUILTIN_PREDICTORS, name, "predictor", "docs/custom_predictor.md")
    predictor = cls(lot, config)
    if not callable(getattr(predictor, "predict", None)):
        raise ValueError(f"predictor {name!r}: {available_predictors()[name]!r} made an object without a "
                         "predict(obs, intentions)")
    return predictor


def trajectories_of(trajectories: Sequence[PredictedTrajectory], agent_id: int) -> list[PredictedTrajectory]:
    """The trajectories predicted for one agent."""
    return [t for t in trajectories if t.agent_id == int(agent_id)]

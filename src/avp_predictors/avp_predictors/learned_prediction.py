"""Learned, intention-conditioned trajectory predictor (paper §VI-B-1 "Learned Model (ParkPredict+)").

ParkPredict+'s trajectory transformer (reference sheet §2.2), sized for a CPU; model card docs/trajectory_model.md.

**Inputs** of one (vehicle V_k, intention) pair, all in V_k's frame at time t (origin at its pose, x along its
heading; :func:`to_agent_frame`):

* the history: 10 poses (x, y, dpsi) at t - 3.6 s ... t every 0.4 s (the model step ``MODEL_DT``), taken
  from the observed history (§III-A; the oldest pose repeats where the history is shorter: a car that just
  appeared looks as if it had stood still);
* the BEV I_k,0 of §V-B (100 x 100 px at 0.4 m/px, V_k red with its trail, drawn by the intent pipeline's
  renderer, :mod:`.bev`) encoded by the intent CNN's conv stack (3 x 9 x 9 = 243 features, initialised from
  the shipped intent weights; blocks 1-2 stay at those weights, block 3 is fine-tuned — ParkPredict+ fine-tuned
  all three, which costs most of the training time on this CPU);
* the goal (x, y) of the intention: the spot centre for a spot intention eta_k,i >= mu, the exploration point
  for an exploration intention eta_hat_k,q >= mu — the goals the Bezier predictor (§V-C) uses.

**Network** (:class:`TrajectoryTransformer`): encoder tokens [pose_j / s || conv features] -> Linear -> d_model
(64) + a sinusoidal encoding of the *time step j* (batch-first done right: ParkPredict+ added it by batch
index, sheet §2.2, so no position was encoded) -> 2 encoder layers. Decoder tokens: the previous pose (the
current pose, then the predictions) -> Linear -> + the same positional encoding -> layers of masked
self-attention, cross-attention to the encoder memory, cross-attention to the intent ([IntentFF(goal), 0],
as ParkPredict+), feed-forward (GELU), post-norm; the decoder also sees each input pose's last increment. The
head outputs a *correction* to constant velocity: pose_j+1 = pose_j + (pose_j - pose_j-1) + head (pose_-1 = the
history pose at t - 0.4 s), so an untrained head predicts constant velocity and turn rate (ParkPredict+ seeded
its decoder with a constant-velocity guess, sheet §2.2). Training: teacher forcing, L1 on
(x, y, psi) in metres / radians (:mod:`avp_trajectory_training.train`). Inference: autoregressive, 10
steps (4 s), batched over every (vehicle, intention) pair of the step.

**Output** (:class:`LearnedPredictor`, name ``"learned"``, the interface of :mod:`.prediction`): one
:class:`PredictedTrajectory` per intention >= mu, carrying its probability, spot id and goal, at the
simulator's dt: the 0.4 s poses are interpolated linearly (position, unwrapped heading) from the current
pose, and beyond 4 s (a longer ``horizon``) continued at the velocity of the last 0.4 s step. Everything
the Bezier predictor predicts at constant velocity stays constant velocity here: a vehicle without
intentions, the "none" mass >= mu with no exploration point to condition on, a vehicle with no intention
>= mu, pedestrians (§V-C).

**State.** The BEV needs the belief map. The predictor keeps its own: eq. (7) only (observation updates of
b~, as the intent training data, :mod:`avp_training.dataset`) and the ego's recent poses for its
trail — both from the observations alone (no ground truth), reset when time goes back. Call ``predict``
once per observation, in order (the prediction node answers a re-sent observation from its cache).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np
import torch

from avp_belief_map.belief import BELIEF_INIT, BeliefMap
from avp_belief_map.bev import BEVConfig, BEVRenderer
from avp_belief_map.ego_trail import EgoTrail
from avp_predictors.intent_model import (
    images_to_tensor,
)
from avp_predictors.intention import Intention
from avp_predictors.prediction import (
    BezierPredictor,
    PredictionConfig,
    constant_velocity_pedestrian,
    constant_velocity_vehicle,
)
from avp_predictors.trajectory_net import (  # noqa: F401 - re-exported: the predictor's API
    MODEL_DT,
    N_FUT,
    N_HIST,
    POS_SCALE,
    VEL_SCALE,
    WEIGHTS_FILE,
    TrajectoryTransformer,
    TransformerConfig,
    default_weights_path,
    load_model,
    make_model,
    save_model,
    sinusoidal_encoding,
    weights_path,
)
from avp_world.geometry import wrap_angle
from avp_world.lot import LotMap
from avp_world.types import Observation, ObservedVehicle, PredictedTrajectory

# ----------------------------------------------------------------------------------------- frames


def to_agent_frame(poses: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """World poses (..., 3) -> (x, y, dpsi) in the frame of ``origin`` (x along its heading), dpsi wrapped."""
    p = np.asarray(poses, dtype=float)
    o = np.asarray(origin, dtype=float)
    c, s = math.cos(o[2]), math.sin(o[2])
    d = p[..., :2] - o[:2]
    out = np.empty(p.shape[:-1] + (3,))
    out[..., 0] = c * d[..., 0] + s * d[..., 1]
    out[..., 1] = -s * d[..., 0] + c * d[..., 1]
    out[..., 2] = wrap_angle(p[..., 2] - o[2]) if p.shape[-1] > 2 else 0.0
    return out


def to_world_frame(local: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Inverse of :func:`to_agent_frame`: (..., 3) agent-frame poses -> world poses (heading wrapped)."""
    q = np.asarray(local, dtype=float)
    o = np.asarray(origin, dtype=float)
    c, s = math.cos(o[2]), math.sin(o[2])
    out = np.empty(q.shape[:-1] + (3,))
    out[..., 0] = o[0] + c * q[..., 0] - s * q[..., 1]
    out[..., 1] = o[1] + s * q[..., 0] + c * q[..., 1]
    out[..., 2] = wrap_angle(q[..., 2] + o[2])
    return out


def history_poses(history: np.ndarray, dt: float, n: int = N_HIST, step: float = MODEL_DT) -> np.ndarray:
    """(n, 3) world poses at t - (n - 1) step ... t from a (H, 3) history sampled every ``dt`` (oldest first);
    where the history is shorter, its oldest pose repeats."""
    h = np.asarray(history, dtype=float).reshape(-1, 3)
    stride = max(1, int(round(step / dt)))
    idx = len(h) - 1 - stride * np.arange(n - 1, -1, -1)
    return h[np.maximum(idx, 0)]


def resample(local: np.ndarray, model_dt: float, dt: float, n_steps: int) -> np.ndarray:
    """(B, T, 3) agent-frame poses at model_dt, 2 model_dt, ... -> (B, n_steps, 3) at dt, 2 dt, ...: linear in
    position and unwrapped heading from the origin (0, 0, 0); beyond the last pose, the last step's velocity
    continues (heading kept)."""
    q = np.asarray(local, dtype=float)
    b, t_len = q.shape[0], q.shape[1]
    full = np.concatenate([np.zeros((b, 1, 3)), q], axis=1)
    full[:, :, 2] = np.unwrap(full[:, :, 2], axis=1)
    t_src = model_dt * np.arange(t_len + 1)
    t = dt * np.arange(1, n_steps + 1)
    j = np.clip(np.searchsorted(t_src, t, side="right") - 1, 0, t_len - 1)
    w = (t - t_src[j]) / model_dt  # > 1 past the end: linear extrapolation of the last segment
    out = full[:, j] + w[None, :, None] * (full[:, j + 1] - full[:, j])
    past = t > t_src[-1]
    out[:, past, 2] = full[:, -1:, 2]
    return out


# ----------------------------------------------------------------------------------------- predictor


class LearnedPredictor(BezierPredictor):
    """The ``"learned"`` predictor (module docstring). Goals, probabilities and the constant-velocity cases are
    the Bezier predictor's (:meth:`BezierPredictor.goals`); only the curve is replaced by the network."""

    name = "learned"

    def __init__(self, lot: LotMap, config: PredictionConfig = PredictionConfig(), bev_config: BEVConfig = BEVConfig(),
                 model: TrajectoryTransformer | None = None):
        super().__init__(lot, config)
        s = config.learned
        if model is None:
            model, self.info = make_model(s.weights, s.seed)
        else:
            self.info = "trajectory transformer: weights given"
        if model.config.image_size != bev_config.size_px:
            raise ValueError(f"trajectory model input {model.config.image_size} px != BEV size {bev_config.size_px} px")
        torch.set_num_threads(int(s.threads))
        self.model = model.eval()
        self.renderer = BEVRenderer(lot, bev_config)
        self.beliefs = BeliefMap.from_lot(lot, BELIEF_INIT)
        self.trail = EgoTrail(s.t_hist)

    def reset(self) -> None:
        self.beliefs.reset()
        self.trail.clear()

    def _observe(self, obs: Observation) -> np.ndarray:
        """Eq. (7) on the predictor's own belief and the ego trail; returns the ego history (H, 3)."""
        if self.trail.went_back(obs):  # a new episode
            self.reset()
        if not self.trail.repeats(obs):  # a re-sent observation changes nothing
            self.beliefs.observe(obs.vacant_spot_ids, obs.occupied_spot_ids)
        return self.trail.update(obs)

    @torch.inference_mode()
    def infer(self, images: np.ndarray, histories: np.ndarray, goals: np.ndarray, owner: np.ndarray) -> np.ndarray:
        """Agent-frame futures (P, N_FUT, 3) of P (vehicle, goal) pairs: images (V, H, W, 3) uint8 and agent-frame
        histories (V, N_HIST, 3) per vehicle, agent-frame goals (P, 2), ``owner`` (P,) the vehicle row of each pair.
        The conv stack and the encoder run once per vehicle."""
        if len(goals) == 0:
            return np.zeros((0, N_FUT, 3))
        hist = torch.as_tensor(histories, dtype=torch.float32)
        memory = self.model.encode(images_to_tensor(images), hist)
        idx = torch.as_tensor(np.asarray(owner, dtype=np.int64))
        out = self.model.rollout(memory[idx], torch.as_tensor(np.asarray(goals), dtype=torch.float32), hist[idx, -2])
        return out.double().numpy()

    def trajectories(self, vehicles: Sequence[ObservedVehicle], images: np.ndarray,
                     intentions: Sequence[Intention | None], dt: float, n_steps: int) -> list[PredictedTrajectory]:
        """The predictions of ``vehicles`` (their BEVs I_k,0 ``images`` (V, H, W, 3); rows of vehicles without a
        goal are not read) under their intentions (None: constant velocity), in the Bezier predictor's order:
        per vehicle its goals, then the constant-velocity "none" mode. One network call for all pairs."""
        mu = self.config.mu
        goals_of = [self.goals(it) if it is not None else [] for it in intentions]
        rows = [r for r, g in enumerate(goals_of) if g]
        pairs = [(j, g) for j, r in enumerate(rows) for g in goals_of[r]]
        poses = np.zeros((0, n_steps, 3))
        if pairs:
            hists = np.stack([to_agent_frame(history_poses(vehicles[r].history, dt), vehicles[r].pose) for r in rows])
            owner = np.array([j for j, _ in pairs])
            local_goals = np.stack([to_agent_frame(np.append(np.asarray(g[0], float)[:2], 0.0),
                                                   vehicles[rows[j]].pose)[:2] for j, g in pairs])
            fut = self.infer(np.asarray(images)[rows], hists, local_goals, owner)
            poses = resample(fut, MODEL_DT, dt, n_steps)
        out: list[PredictedTrajectory] = []
        k = 0
        for r, (v, it) in enumerate(zip(vehicles, intentions, strict=True)):
            for goal, p, sid in goals_of[r]:
                out.append(PredictedTrajectory(agent_id=int(v.id), poses=to_world_frame(poses[k], v.pose), dt=dt,
                                               probability=p, length=float(v.length), width=float(v.width),
                                               spot_id=sid, goal=np.asarray(goal, dtype=float).copy()))
                k += 1
            none_cv = it is not None and it.none_probability >= mu and len(it.exploration_points) == 0
            if none_cv:
                out.append(constant_velocity_vehicle(v, dt, n_steps, it.none_probability))
            if not goals_of[r] and not none_cv:
                out.append(constant_velocity_vehicle(v, dt, n_steps))
        return out

    def predict(self, obs: Observation, intentions: Iterable[Intention] = (),
                horizon: float | None = None) -> list[PredictedTrajectory]:
        ego_hist = self._observe(obs)
        n = int(round(self.horizon(horizon) / obs.dt)) if obs.dt > 0 else 0
        by_id = {int(it.vehicle_id): it for it in intentions}
        dyn = [v for v in obs.vehicles if not v.is_static]
        its = [by_id.get(int(v.id)) for v in dyn]
        need = [i for i, it in enumerate(its) if it is not None and self.goals(it)]
        size = self.renderer.config.size_px
        images = np.zeros((len(dyn), size, size, 3), np.uint8)
        if need:
            bevs = self.renderer.render_all(obs, [dyn[i] for i in need], self.beliefs.b_tilde,
                                            self.beliefs.observed_mask, ego_hist)
            for i, b in zip(need, bevs, strict=True):
                images[i] = b.image
        out = self.trajectories(dyn, images, its, obs.dt, n)
        out += [constant_velocity_pedestrian(p, obs.dt, n) for p in obs.pedestrians]
        return out

"""Learned, intention-conditioned trajectory predictor (paper §VI-B-1 "Learned Model (ParkPredict+)", issue #5).

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
(x, y, psi) in metres / radians (:mod:`avp_training.trajectory`). Inference: autoregressive, 10
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
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from avp_perception.core.belief import BELIEF_INIT, BeliefMap
from avp_perception.core.bev import BEVConfig, BEVRenderer
from avp_perception.core.ego_trail import EgoTrail
from avp_perception.core.intent_model import (
    CHANNELS,
    KERNELS,
    SLOPE,
    SmallRegularizedCNN,
    conv_output_size,
    images_to_tensor,
)
from avp_perception.core.intention import Intention
from avp_perception.core.prediction import (
    BezierPredictor,
    PredictionConfig,
    constant_velocity_pedestrian,
    constant_velocity_vehicle,
)
from avp_world.geometry import wrap_angle
from avp_world.lot import LotMap
from avp_world.types import Observation, ObservedVehicle, PredictedTrajectory

MODEL_DT = 0.4  # s between model poses (ParkPredict+'s stride, sheet §2.1)
N_HIST = 10  # history poses t - 3.6 s ... t
N_FUT = 10  # future poses t + 0.4 s ... t + 4.0 s
POS_SCALE = 10.0  # m: positions are divided by this inside the network
VEL_SCALE = 5.0  # pose increments (per 0.4 s) are multiplied by this on top
WEIGHTS_FILE = "trajectory_transformer.pt"


@dataclass(frozen=True)
class TransformerConfig:
    """Architecture (sheet §2.2 sized for a CPU; the card records the values of the shipped weights)."""

    image_size: int = 100
    d_model: int = 64
    n_heads: int = 4
    enc_layers: int = 2
    dec_layers: int = 2
    d_ff: int = 128
    d_intent: int = 128  # IntentFF hidden width (ParkPredict+: 128)
    dropout: float = 0.1


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


# ----------------------------------------------------------------------------------------- network


def sinusoidal_encoding(n: int, d: int) -> torch.Tensor:
    """(n, d) sinusoidal encoding of positions 0..n-1 (Vaswani et al.); added per time step to (B, n, d)."""
    pos = torch.arange(n, dtype=torch.float32)[:, None]
    div = torch.exp(torch.arange(0, d, 2, dtype=torch.float32) * (-math.log(10000.0) / d))
    pe = torch.zeros(n, d)
    pe[:, 0::2] = torch.sin(pos * div)
    pe[:, 1::2] = torch.cos(pos * div)
    return pe


class Attention(nn.Module):
    """Multi-head attention on batch-first tensors (scaled dot product)."""

    def __init__(self, d: int, heads: int):
        super().__init__()
        self.heads = heads
        self.q = nn.Linear(d, d)
        self.kv = nn.Linear(d, 2 * d)
        self.out = nn.Linear(d, d)

    def keys(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        b, n, d = x.shape
        k, v = self.kv(x).view(b, n, 2, self.heads, d // self.heads).permute(2, 0, 3, 1, 4)
        return k, v

    def forward(self, x: torch.Tensor, kv: tuple[torch.Tensor, torch.Tensor], causal: bool = False,
                dropout: float = 0.0) -> torch.Tensor:
        b, n, d = x.shape
        q = self.q(x).view(b, n, self.heads, d // self.heads).transpose(1, 2)
        y = F.scaled_dot_product_attention(q, kv[0], kv[1], dropout_p=dropout, is_causal=causal)
        return self.out(y.transpose(1, 2).reshape(b, n, d))


class EncoderLayer(nn.Module):
    def __init__(self, c: TransformerConfig):
        super().__init__()
        self.attn = Attention(c.d_model, c.n_heads)
        self.ff = nn.Sequential(nn.Linear(c.d_model, c.d_ff), nn.GELU(), nn.Linear(c.d_ff, c.d_model))
        self.n1, self.n2 = nn.LayerNorm(c.d_model), nn.LayerNorm(c.d_model)
        self.drop = nn.Dropout(c.dropout)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.n1(x + self.drop(self.attn(x, self.attn.keys(x))))
        return self.n2(x + self.drop(self.ff(x)))


class DecoderLayer(nn.Module):
    """Masked self-attention -> cross-attention to the memory -> cross-attention to the intent -> FF (post-norm)."""

    def __init__(self, c: TransformerConfig):
        super().__init__()
        self.self_attn = Attention(c.d_model, c.n_heads)
        self.mem_attn = Attention(c.d_model, c.n_heads)
        self.int_attn = Attention(c.d_model, c.n_heads)
        self.ff = nn.Sequential(nn.Linear(c.d_model, c.d_ff), nn.GELU(), nn.Linear(c.d_ff, c.d_model))
        self.norms = nn.ModuleList([nn.LayerNorm(c.d_model) for _ in range(4)])
        self.drop = nn.Dropout(c.dropout)

    def forward(self, x: torch.Tensor, mem_kv, int_kv) -> torch.Tensor:
        n = self.norms
        x = n[0](x + self.drop(self.self_attn(x, self.self_attn.keys(x), causal=True)))
        x = n[1](x + self.drop(self.mem_attn(x, mem_kv)))
        x = n[2](x + self.drop(self.int_attn(x, int_kv)))
        return n[3](x + self.drop(self.ff(x)))


class TrajectoryTransformer(nn.Module):
    """ParkPredict+'s TrajectoryPredictorWithDecoderIntentCrossAttention (sheet §2.2), see the module docstring.

    Shapes: images (B, 3, H, W) in [0, 1]; history (B, N_HIST, 3) and poses (B, T, 3) in the agent frame
    (metres, radians); goal (B, 2) agent frame (metres).
    """

    def __init__(self, config: TransformerConfig = TransformerConfig()):
        super().__init__()
        c = self.config = config
        self.conv = nn.Sequential(*[nn.Sequential(nn.Conv2d(CHANNELS[i], CHANNELS[i + 1], KERNELS[i]),
                                                  nn.BatchNorm2d(CHANNELS[i + 1]), nn.LeakyReLU(SLOPE),
                                                  nn.MaxPool2d(2)) for i in range(3)])
        n_img = CHANNELS[-1] * conv_output_size(c.image_size) ** 2
        self.enc_in = nn.Linear(3 + n_img, c.d_model)
        self.dec_in = nn.Linear(6, c.d_model)
        self.intent = nn.Sequential(nn.Linear(2, c.d_intent), nn.ReLU(), nn.LayerNorm(c.d_intent),
                                    nn.Dropout(c.dropout), nn.Linear(c.d_intent, c.d_model), nn.LayerNorm(c.d_model),
                                    nn.Dropout(c.dropout))
        self.encoder = nn.ModuleList([EncoderLayer(c) for _ in range(c.enc_layers)])
        self.decoder = nn.ModuleList([DecoderLayer(c) for _ in range(c.dec_layers)])
        self.head = nn.Linear(c.d_model, 3)
        self.register_buffer("pe", sinusoidal_encoding(N_HIST + N_FUT + 1, c.d_model), persistent=False)
        self.register_buffer("scale", torch.tensor([1.0 / POS_SCALE, 1.0 / POS_SCALE, 1.0]), persistent=False)

    def init_conv_from_intent(self, intent: SmallRegularizedCNN) -> None:
        """Copy the intent CNN's conv blocks (conv + BatchNorm) into this encoder (sheet §2.2)."""
        for mine, theirs in zip(self.conv, intent.conv, strict=True):
            mine[0].load_state_dict(theirs[0].state_dict())
            mine[1].load_state_dict(theirs[1].state_dict())

    def conv_front(self, images: torch.Tensor) -> torch.Tensor:
        """Conv blocks 1-2 (kept at the intent CNN's weights in training): (B, 3, H, W) -> (B, 8, h2, w2)."""
        return self.conv[1](self.conv[0](images))

    def encode(self, images: torch.Tensor, history: torch.Tensor) -> torch.Tensor:
        """(B, N_HIST, d_model) encoder memory."""
        return self.encode_front(self.conv_front(images), history)

    def encode_front(self, front: torch.Tensor, history: torch.Tensor) -> torch.Tensor:
        """:meth:`encode` from the output of :meth:`conv_front`."""
        feat = self.conv[2](front).flatten(1)
        x = torch.cat([history * self.scale, feat[:, None].expand(-1, history.shape[1], -1)], dim=2)
        x = self.enc_in(x) + self.pe[: history.shape[1]]
        for layer in self.encoder:
            x = layer(x)
        return x

    def intent_tokens(self, goal: torch.Tensor) -> torch.Tensor:
        """(B, 2, d_model): [IntentFF(goal), 0] (ParkPredict+'s key/value sequence)."""
        tok = self.intent(goal / POS_SCALE)
        return torch.stack([tok, torch.zeros_like(tok)], dim=1)

    def cross_keys(self, memory: torch.Tensor, intent: torch.Tensor) -> list[tuple]:
        """Per decoder layer the keys / values of the memory and of the intent tokens (computed once per rollout)."""
        return [(layer.mem_attn.keys(memory), layer.int_attn.keys(intent)) for layer in self.decoder]

    def decode(self, inputs: torch.Tensor, prev0: torch.Tensor, memory: torch.Tensor, intent: torch.Tensor,
               keys: list[tuple] | None = None) -> torch.Tensor:
        """Decoder inputs (B, T, 3) (the pose before each predicted one; ``prev0`` (B, 3) the pose before the
        first, i.e. the history pose at t - 0.4 s) -> predicted poses (B, T, 3): each input pose plus its last
        increment (constant velocity and turn rate) plus the network's correction."""
        keys = keys if keys is not None else self.cross_keys(memory, intent)
        step = inputs - torch.cat([prev0[:, None], inputs[:, :-1]], dim=1)
        x = self.dec_in(torch.cat([inputs * self.scale, step * (VEL_SCALE * self.scale)], dim=2))
        x = x + self.pe[N_HIST: N_HIST + inputs.shape[1]]
        for layer, (mem_kv, int_kv) in zip(self.decoder, keys, strict=True):
            x = layer(x, mem_kv, int_kv)
        return inputs + step + self.head(x)

    def forward(self, front: torch.Tensor, history: torch.Tensor, goal: torch.Tensor,
                future: torch.Tensor) -> torch.Tensor:
        """Teacher forcing from :meth:`conv_front` features: decoder inputs [current pose (0, 0, 0), future[:-1]]
        -> predicted future (B, T, 3)."""
        memory = self.encode_front(front, history)
        inputs = torch.cat([torch.zeros_like(future[:, :1]), future[:, :-1]], dim=1)
        return self.decode(inputs, history[:, -2], memory, self.intent_tokens(goal))

    @torch.inference_mode()
    def rollout(self, memory: torch.Tensor, goal: torch.Tensor, prev0: torch.Tensor, n: int = N_FUT) -> torch.Tensor:
        """Autoregressive decoding of ``n`` poses (B, n, 3) from memories (B, N_HIST, d), goals (B, 2) and the
        history poses at t - 0.4 s (B, 3)."""
        return self.free_run(memory, goal, prev0, n)

    def free_run(self, memory: torch.Tensor, goal: torch.Tensor, prev0: torch.Tensor, n: int = N_FUT) -> torch.Tensor:
        """:meth:`rollout` with gradients (the free-running training loss)."""
        intent = self.intent_tokens(goal)
        keys = self.cross_keys(memory, intent)
        seq = torch.zeros(memory.shape[0], 1, 3)
        for _ in range(n):
            out = self.decode(seq, prev0, memory, intent, keys)
            seq = torch.cat([seq, out[:, -1:]], dim=1)
        return seq[:, 1:]


# ----------------------------------------------------------------------------------------- weights


def default_weights_path() -> Path:
    """``avp_perception/models/trajectory_transformer.pt`` (made by ``avp train-trajectory``; card beside it)."""
    return Path(__file__).resolve().parents[1] / "models" / WEIGHTS_FILE


def save_model(model: TrajectoryTransformer, path: str | Path) -> None:
    """State dict + architecture in one file."""
    from dataclasses import asdict

    torch.save({"config": asdict(model.config), "state_dict": model.state_dict()}, Path(path))


def load_model(path: str | Path) -> TrajectoryTransformer:
    """A model saved by :func:`save_model`; ValueError names a file that cannot be loaded."""
    p = Path(path)
    try:
        blob = torch.load(p, map_location="cpu", weights_only=True)
        model = TrajectoryTransformer(TransformerConfig(**blob["config"]))
        model.load_state_dict(blob["state_dict"])
    except Exception as exc:  # noqa: BLE001 - any unreadable / mismatched file is one clear error
        raise ValueError(f"trajectory weights {p}: cannot load ({exc})") from None
    return model.eval()


def make_model(weights: str = "", seed: int = 0) -> tuple[TrajectoryTransformer, str]:
    """The model and a line saying which weights: ``weights`` file, else the shipped file if present, else
    seeded random weights (valid but uninformative output)."""
    p = Path(weights) if weights else default_weights_path()
    if weights and not p.is_file():
        raise ValueError(f"trajectory weights {p}: no such file")
    if p.is_file():
        return load_model(p), f"trajectory transformer: weights from {p}" + ("" if weights else " (shipped)")
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(seed))
        model = TrajectoryTransformer().eval()
    return model, f"trajectory transformer: untrained seeded random weights (seed {seed}); no shipped weights found"


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

"""Training and evaluation of the learned trajectory predictor (model card docs/trajectory_model.md).

The data (:func:`~.trajectory_data.generate`) is :mod:`.trajectory_data`.

**Training** (:func:`train`): teacher forcing, L1 on (x, y, psi) of the 10 future poses (metres, radians),
AdamW with cosine decay, fixed seeds, best epoch by the validation ADE of the *autoregressive* rollout. Teacher
forcing alone (ParkPredict+) left a large exposure bias in the dev run (teacher-forced L1 0.044 against a
validation rollout ADE of 1.47 m, worse than constant velocity): the loss adds the same L1 on the free-running
rollout (``free_run_weight``, gradients through the 10 autoregressive steps). The conv
stack starts from the shipped intent CNN; blocks 1-2 stay frozen (their features are computed once per sample),
block 3 and everything after are trained.

**Evaluation** (:func:`evaluate`): minADE / minFDE over 4 s at the simulator's dt, the definition of the Table I
runner (``avp_episode.metrics.prediction_errors``: per sample the best mode's ADE and, separately, the
best mode's FDE), of the learned, the Bezier (§V-C) and the constant-velocity predictors on the same samples —
once conditioned on the true goal (one mode: the trajectory model alone) and once on the intent CNN's
intentions >= mu (all modes, as in closed loop).
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from avp_belief_map.bev import BEVConfig
from avp_predictors.intention import Intention
from avp_predictors.learned_prediction import (
    N_FUT,
    LearnedPredictor,
    TrajectoryTransformer,
    TransformerConfig,
)
from avp_predictors.prediction import BezierPredictor, PredictionConfig, constant_velocity_vehicle
from avp_training.dataset import (
    LOT_NAMES,
)
from avp_trajectory_training.data import (  # noqa: F401 - re-exported: the data side of this module's API
    HORIZON,
    MAX_GOALS,
    TRAJ_SEED0,
    TrajDataSpec,
    TrajSamples,
    episode_samples,
    generate,
    intention_goals,
    split_seeds,
)
from avp_world.lot import load_bundled_lot

# ------------------------------------------------------------------------------------------------ training


@dataclass(frozen=True)
class TrajTrainConfig:
    seed: int = 0
    epochs: int = 12
    batch: int = 128
    lr: float = 1e-3
    lr_final: float = 0.05  # cosine decay to this fraction of lr
    weight_decay: float = 1e-4
    free_run_weight: float = 1.0  # weight of the L1 of the free-running rollout (0: teacher forcing only)
    threads: int = 2
    model: TransformerConfig = field(default_factory=TransformerConfig)


@torch.no_grad()
def _tensors(model: TrajectoryTransformer, s: TrajSamples, batch: int = 512) -> tuple[torch.Tensor, ...]:
    """(conv_front features, history, future, goal) of every sample (blocks 1-2 are frozen: computed once)."""
    from avp_predictors.intent_model import images_to_tensor

    hist, fut, goal = s.local()
    was = model.training
    model.conv[:2].eval()
    front = [model.conv_front(images_to_tensor(s.images[a:a + batch])) for a in range(0, len(s), batch)]
    model.train(was)
    front_t = torch.cat(front) if front else torch.zeros(0)
    return (front_t, torch.as_tensor(hist, dtype=torch.float32), torch.as_tensor(fut, dtype=torch.float32),
            torch.as_tensor(goal, dtype=torch.float32))


@torch.no_grad()
def rollout_errors(model: TrajectoryTransformer, s: TrajSamples, batch: int = 256,
                   tensors: tuple | None = None) -> tuple[float, float]:
    """(ADE, FDE) in metres of the autoregressive 0.4 s rollout conditioned on the true goal."""
    model.eval()
    front, hist, fut, goal = tensors if tensors is not None else _tensors(model, s)
    errs = []
    for a in range(0, len(s), batch):
        mem = model.encode_front(front[a:a + batch], hist[a:a + batch])
        out = model.rollout(mem, goal[a:a + batch], hist[a:a + batch, -2])
        errs.append(torch.linalg.norm(out[..., :2] - fut[a:a + batch, :, :2], dim=2))
    e = torch.cat(errs) if errs else torch.zeros(0, N_FUT)
    return (float(e.mean()), float(e[:, -1].mean())) if len(e) else (math.nan, math.nan)


def train(train_set: TrajSamples, val_set: TrajSamples, config: TrajTrainConfig = TrajTrainConfig(),
          intent_weights: str | Path | None = None, progress: bool = True, log=print
          ) -> tuple[TrajectoryTransformer, list[dict]]:
    """Teacher-forced L1 training; the conv stack starts from the intent CNN (``intent_weights``: the shipped
    file when None, skipped when absent); returns the model of the best validation rollout ADE and the history."""
    from tqdm import tqdm

    from avp_predictors.intent_model import default_weights_path, load_cnn

    torch.set_num_threads(int(config.threads))
    torch.manual_seed(config.seed)
    model = TrajectoryTransformer(config.model)
    wpath = Path(intent_weights) if intent_weights else default_weights_path()
    if wpath.is_file():
        cnn = load_cnn(wpath, config.model.image_size)
        model.init_conv_from_intent(cnn)
        log(f"[train-trajectory] conv stack initialised from {wpath}")
    for p in model.conv[:2].parameters():
        p.requires_grad_(False)
    front, hist, fut, goal = _tensors(model, train_set)
    val_tensors = _tensors(model, val_set)
    n = len(train_set)
    steps = max(1, config.epochs * math.ceil(n / config.batch))
    opt = torch.optim.AdamW([p for p in model.parameters() if p.requires_grad], lr=config.lr,
                            weight_decay=config.weight_decay)
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda i: config.lr_final + (1 - config.lr_final) * 0.5 * (1 + math.cos(math.pi * min(i, steps) / steps)))
    gen = torch.Generator().manual_seed(config.seed)
    best, best_state, history = math.inf, None, []
    bar = tqdm(total=steps, desc="train trajectory", disable=not progress, dynamic_ncols=True, mininterval=1.0)
    for epoch in range(config.epochs):
        model.train()
        model.conv[:2].eval()  # frozen blocks (not run in training: their features are precomputed)
        t0, total = time.monotonic(), 0.0
        perm = torch.randperm(n, generator=gen)
        for a in range(0, n, config.batch):
            idx = perm[a:a + config.batch]
            memory = model.encode_front(front[idx], hist[idx])
            intent = model.intent_tokens(goal[idx])
            inputs = torch.cat([torch.zeros_like(fut[idx][:, :1]), fut[idx][:, :-1]], dim=1)
            loss = (model.decode(inputs, hist[idx][:, -2], memory, intent) - fut[idx]).abs().mean()  # teacher forcing
            if config.free_run_weight > 0:  # and the autoregressive rollout (exposure bias, module docstring)
                roll = model.free_run(memory, goal[idx], hist[idx][:, -2])
                loss = loss + config.free_run_weight * (roll - fut[idx]).abs().mean()
            opt.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
            opt.step()
            sched.step()
            total += float(loss.detach()) * len(idx)
            bar.update(1)
            bar.set_postfix(epoch=epoch + 1, loss=f"{float(loss.detach()):.3f}")
        ade, fde = rollout_errors(model, val_set, tensors=val_tensors)
        history.append({"epoch": epoch + 1, "train_l1": total / max(n, 1), "val_ade": ade, "val_fde": fde,
                        "seconds": round(time.monotonic() - t0, 1)})
        log(f"[train-trajectory] epoch {epoch + 1}: train L1 {total / max(n, 1):.4f}, val rollout ADE {ade:.3f} m, "
            f"FDE {fde:.3f} m")
        if ade < best:
            best, best_state = ade, copy.deepcopy(model.state_dict())
    bar.close()
    if best_state is not None:
        model.load_state_dict(best_state)
    return model.eval(), history


# ------------------------------------------------------------------------------------------------ evaluation


def min_errors(modes: list[np.ndarray], truth: np.ndarray) -> tuple[float, float]:
    """(minADE, minFDE) of trajectories (T, >= 2) against truth (T, >= 2) over the same steps: the runner's
    definition (each minimised on its own)."""
    err = np.linalg.norm(np.stack([m[:, :2] for m in modes]) - truth[None, :, :2], axis=2)
    return float(err.mean(axis=1).min()), float(err[:, -1].min())


def evaluate(model: TrajectoryTransformer, s: TrajSamples, dt: float = 0.1, mu: float = 0.3) -> dict:
    """minADE / minFDE (m) over 4 s of learned, Bezier and constant velocity on the same samples (module docstring);
    ``oracle``: conditioned on the true goal (one mode); ``intent``: on the intent CNN's intentions (samples that
    have them). Also per lot, and for moving cars (speed > 0.5 m/s)."""
    lot = load_bundled_lot()  # goals are given as poses: the lot is not read
    cfg = PredictionConfig(mu=mu)
    learned = LearnedPredictor(lot, cfg, BEVConfig(size_px=model.config.image_size), model=model)
    bezier = BezierPredictor(lot, cfg)
    n_h = int(round(HORIZON / dt))
    res: dict[str, list] = {k: [] for k in ("oracle_learned", "oracle_bezier", "cv", "intent_learned",
                                            "intent_bezier", "intent_cv")}
    for a in range(0, len(s), 64):
        idx = range(a, min(len(s), a + 64))
        vehicles = [s.vehicle_at(i, vid=i) for i in idx]  # one id per sample: modes are matched by id
        truth = [s.future[i] for i in idx]
        oracle_its = [_as_intention(v.id, s.goal[i][None], np.ones(1), 0.0) for v, i in zip(vehicles, idx, strict=True)]
        lt = learned.trajectories(vehicles, s.images[a:a + len(vehicles)], oracle_its, dt, n_h)
        for v, it, tr in zip(vehicles, oracle_its, truth, strict=True):
            lm = [t.poses for t in lt if t.agent_id == v.id]
            bm = [t.poses for t in bezier.predict_vehicle(v, it, dt, n_h)]
            cm = [constant_velocity_vehicle(v, dt, n_h).poses]
            res["oracle_learned"].append(min_errors(lm, tr))
            res["oracle_bezier"].append(min_errors(bm, tr))
            res["cv"].append(min_errors(cm, tr))
        sel = [j for j, i in enumerate(idx) if s.has_int[i]]
        if sel:
            its = [_as_intention(vehicles[j].id, s.int_goals[idx[j]], s.int_probs[idx[j]], s.int_cv[idx[j]])
                   for j in sel]
            vs = [vehicles[j] for j in sel]
            lt = learned.trajectories(vs, s.images[[idx[j] for j in sel]], its, dt, n_h)
            for j, v, it in zip(sel, vs, its, strict=True):
                lm = [t.poses for t in lt if t.agent_id == v.id]
                bm = [t.poses for t in bezier.predict_vehicle(v, it, dt, n_h)]
                if s.int_cv[idx[j]] > 0 and len(it.exploration_points):  # the "none" mode (see _as_intention)
                    lm.append(constant_velocity_vehicle(v, dt, n_h).poses)
                    bm.append(constant_velocity_vehicle(v, dt, n_h).poses)
                res["intent_learned"].append(min_errors(lm, truth[j]))
                res["intent_bezier"].append(min_errors(bm, truth[j]))
                res["intent_cv"].append(min_errors([constant_velocity_vehicle(v, dt, n_h).poses], truth[j]))
    arr = {k: np.asarray(v, float).reshape(-1, 2) for k, v in res.items()}
    speed = np.hypot(*(s.history[:, -1, :2] - s.history[:, -2, :2]).T) / dt if len(s) else np.zeros(0)
    groups = {"all": np.ones(len(s), bool), "moving": speed > 0.5}
    for code, name in LOT_NAMES.items():
        if (s.lot == code).any():
            groups[name] = s.lot == code
    out: dict = {"n": int(len(s)), "n_intent": int(s.has_int.sum())}
    for g, m in groups.items():
        entry = {"n": int(m.sum())}
        for k in ("oracle_learned", "oracle_bezier", "cv"):
            e = arr[k][m] if len(arr[k]) else arr[k]
            entry[k] = [float(e[:, 0].mean()), float(e[:, 1].mean())] if len(e) else None
        mi = m[s.has_int]
        for k in ("intent_learned", "intent_bezier", "intent_cv"):
            e = arr[k][mi] if len(arr[k]) else arr[k]
            entry[k] = [float(e[:, 0].mean()), float(e[:, 1].mean())] if len(e) else None
        out[g] = entry
    return out


def _as_intention(vid: int, goals: np.ndarray, probs: np.ndarray, cv: float) -> Intention:
    """Stored goals as an :class:`Intention` whose goals are all "exploration points" (both predictors condition
    on the goal pose, so the sample's lot is not needed). The constant-velocity "none" mode comes from the
    predictors when there is no goal; next to goals the caller appends it to both (as the predictors do for
    spot goals with the "none" mass >= mu and no exploration point)."""
    keep = np.asarray(probs) > 0
    return Intention(vehicle_id=int(vid), spot_ids=np.zeros(0, np.int64), spot_probabilities=np.zeros(0),
                     exploration_points=np.asarray(goals, float)[keep].reshape(-1, 3),
                     exploration_probabilities=np.asarray(probs, float)[keep],
                     none_probability=float(cv))


def config_dict(config: TrajTrainConfig) -> dict:
    return asdict(config)

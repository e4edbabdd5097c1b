"""Data, training and evaluation of the learned trajectory predictor (issue #5; model card docs/trajectory_model.md).

**Data** (:func:`generate`): episodes of #4's traffic generator (:mod:`.traffic`) on the DLP-derived and random lots
(training, validation, held-out test by seed) and the paper's §VI-A protocol on the paper lot (test only), run by
#4's episode runner (:func:`.dataset.run_episode`: the observer's occlusion-aware observation, eq. (7), the ego
trail). Every ``stride`` steps each observed dynamic traffic car is a sample: its *observed* history, its BEV
I_k,0 drawn by the inference renderer from the observation-only belief (exactly what
:class:`~avp_perception.core.learned_prediction.LearnedPredictor` renders), and — from ground truth, for labels
only — its future over the next 4 s from the simulator's log and its goal:

* the spot the car parks in, if its centre lies in the 40 m crop and the car reaches it (centre within 1.5 m)
  within ``spot_horizon`` (20 s);
* otherwise the exploration point of §V-A (the ranked points the BEV renderer computes, circle of 11.5 m) nearest
  to where the car's true path first leaves that circle (its last logged position if it never does); with no
  exploration point, that position itself.

Samples whose 4 s future runs past the episode's log, or jumps (> 1 m in one step), are dropped. The test and
paper-lot samples also carry the intentions the shipped intent CNN gives at that step (goals >= mu with their
probabilities, and whether the "none" mass is predicted at constant velocity), for the multimodal evaluation.

**Seeds**: ``TRAJ_SEED0`` — ranges of their own, disjoint from the intent model's splits
(:data:`.dataset.SPLIT_SEED0`, whose training seeds the intent CNN saw) and from each other.

**Training** (:func:`train`): teacher forcing, L1 on (x, y, psi) of the 10 future poses (metres, radians),
AdamW with cosine decay, fixed seeds, best epoch by the validation ADE of the *autoregressive* rollout. Teacher
forcing alone (ParkPredict+) left a large exposure bias in the dev run (teacher-forced L1 0.044 against a
validation rollout ADE of 1.47 m, worse than constant velocity): the loss adds the same L1 on the free-running
rollout (``free_run_weight``, gradients through the 10 autoregressive steps). The conv
stack starts from the shipped intent CNN; blocks 1-2 stay frozen (their features are computed once per sample),
block 3 and everything after are trained.

**Evaluation** (:func:`evaluate`): minADE / minFDE over 4 s at the simulator's dt, the definition of the Table I
runner (``avp_bringup.experiment.metrics.prediction_errors``: per sample the best mode's ADE and, separately, the
best mode's FDE), of the learned, the Bezier (§V-C) and the constant-velocity predictors on the same samples —
once conditioned on the true goal (one mode: the trajectory model alone) and once on the intent CNN's
intentions >= mu (all modes, as in closed loop).
"""

from __future__ import annotations

import copy
import math
import multiprocessing as mp
import time
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

import numpy as np
import torch

from avp_perception.core.bev import BEVConfig
from avp_perception.core.intention import Intention
from avp_perception.core.learned_prediction import (
    MODEL_DT,
    N_FUT,
    LearnedPredictor,
    TrajectoryTransformer,
    TransformerConfig,
    history_poses,
    to_agent_frame,
)
from avp_perception.core.prediction import BezierPredictor, PredictionConfig, constant_velocity_vehicle
from avp_sim.core.observation import SensorConfig
from avp_sim.core.scenario import ScenarioError, generate_paper_scenario
from avp_sim.core.world import WorldConfig
from avp_training.dataset import (
    KIND_CODES,
    LOT_DLP,
    LOT_NAMES,
    LOT_PAPER,
    LOT_RANDOM,
    DataSpec,
    TrainingWorld,
    _generator,
    load_arrays,
    run_episode,
    save_arrays,
)
from avp_training.lots import load_dlp_lot, random_lot
from avp_training.traffic import PARK, TrafficParams
from avp_world.lot import LotMap, load_bundled_lot
from avp_world.types import ObservedVehicle

TRAJ_SEED0 = {"train": 4_000_000, "val": 4_100_000, "test": 4_200_000, "paper": 4_300_000}
HORIZON = 4.0  # s: the Table I runner's minADE horizon (= t_pred)
MAX_GOALS = 3  # intentions >= mu = 0.3: at most 3


@dataclass(frozen=True)
class TrajDataSpec:
    stride: int = 4  # steps between two samples of one vehicle (0.4 s)
    spot_horizon: float = 20.0  # s: a spot is the goal if the car reaches it within this
    spot_reach: float = 1.5  # m
    max_jump: float = 1.0  # m per step: a larger jump in the log drops the sample
    episode: DataSpec = field(default_factory=DataSpec)


@dataclass
class TrajSamples:
    """One split: per sample i the BEV, the observed history, the ground-truth future and goal (world frame)."""

    images: np.ndarray  # (N, H, W, 3) uint8, I_k,0
    history: np.ndarray  # (N, Hh, 3) observed history at dt (world), oldest first
    future: np.ndarray  # (N, 40, 3) ground-truth states at t + dt ... t + 4 s (world)
    goal: np.ndarray  # (N, 3) goal pose (world)
    goal_kind: np.ndarray  # (N,) int8: 0 spot, 1 exploration point, 2 own path (no exploration point)
    int_goals: np.ndarray  # (N, 3, 3) intent CNN goals >= mu (world), padded
    int_probs: np.ndarray  # (N, 3) their probabilities, 0 = padding
    int_cv: np.ndarray  # (N,) probability of the constant-velocity "none" mode (0: none)
    has_int: np.ndarray  # (N,) bool: intentions computed (test / paper splits)
    dims: np.ndarray  # (N, 2) length, width
    episode: np.ndarray  # (N,) int64
    lot: np.ndarray  # (N,) int8
    step: np.ndarray  # (N,) int32
    vehicle: np.ndarray  # (N,) int64
    kind: np.ndarray  # (N,) int8

    def __len__(self) -> int:
        return len(self.episode)

    def save(self, path: str | Path) -> None:
        save_arrays(self, path)

    @classmethod
    def load(cls, path: str | Path) -> TrajSamples:
        return load_arrays(cls, path, "a trajectory sample file")

    @classmethod
    def concat(cls, parts: list[TrajSamples]) -> TrajSamples:
        parts = [p for p in parts if len(p)] or parts[:1]
        return cls(**{f.name: np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(cls)})

    def subset(self, idx: np.ndarray) -> TrajSamples:
        return TrajSamples(**{f.name: getattr(self, f.name)[idx] for f in fields(self)})

    def vehicle_at(self, i: int, vid: int | None = None) -> ObservedVehicle:
        """Sample i as an observed vehicle (id ``vid``, default its own)."""
        return ObservedVehicle(id=int(self.vehicle[i] if vid is None else vid), length=float(self.dims[i, 0]),
                               width=float(self.dims[i, 1]), is_static=False, history=self.history[i].astype(float))

    def local(self, dt: float = 0.1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Network targets in the agent frame: history (N, 10, 3), future (N, 10, 3) at 0.4 s, goal (N, 2);
        headings unwrapped along time from 0 at t."""
        n = len(self)
        pose = self.history[:, -1]
        stride = int(round(MODEL_DT / dt))
        hist = np.stack([to_agent_frame(history_poses(self.history[i], dt), pose[i]) for i in range(n)]) if n else \
            np.zeros((0, 10, 3))
        fut = np.stack([to_agent_frame(self.future[i, stride - 1::stride], pose[i]) for i in range(n)]) if n else \
            np.zeros((0, N_FUT, 3))
        if n:
            hist[:, :, 2] = np.unwrap(hist[:, ::-1, 2], axis=1)[:, ::-1]
            fut[:, :, 2] = np.unwrap(np.concatenate([np.zeros((n, 1)), fut[:, :, 2]], axis=1), axis=1)[:, 1:]
        goal = np.stack([to_agent_frame(np.append(self.goal[i, :2], 0.0), pose[i])[:2] for i in range(n)]) if n else \
            np.zeros((0, 2))
        return hist, fut, goal


def _empty(size_px: int, n_hist: int = 41) -> TrajSamples:
    return TrajSamples(images=np.zeros((0, size_px, size_px, 3), np.uint8), history=np.zeros((0, n_hist, 3)),
                       future=np.zeros((0, 40, 3)), goal=np.zeros((0, 3)), goal_kind=np.zeros(0, np.int8),
                       int_goals=np.zeros((0, MAX_GOALS, 3)), int_probs=np.zeros((0, MAX_GOALS)),
                       int_cv=np.zeros(0), has_int=np.zeros(0, bool), dims=np.zeros((0, 2)),
                       episode=np.zeros(0, np.int64), lot=np.zeros(0, np.int8), step=np.zeros(0, np.int32),
                       vehicle=np.zeros(0, np.int64), kind=np.zeros(0, np.int8))


# ------------------------------------------------------------------------------------------------ data


def intention_goals(it: Intention, lot: LotMap, mu: float) -> tuple[np.ndarray, np.ndarray, float]:
    """(goals (3, 3), probs (3,), cv probability) of an intention as the Bezier predictor conditions on it."""
    bz = BezierPredictor(lot, PredictionConfig(mu=mu))
    g = bz.goals(it)[:MAX_GOALS]
    goals, probs = np.zeros((MAX_GOALS, 3)), np.zeros(MAX_GOALS)
    for j, (pose, p, _) in enumerate(g):
        goals[j], probs[j] = pose, p
    cv = it.none_probability if it.none_probability >= mu and len(it.exploration_points) == 0 else 0.0
    return goals, probs, float(cv)


def _episode(args: tuple[str, int, TrajDataSpec]) -> TrajSamples:
    split, seed, spec = args
    es = spec.episode
    size = es.bev.size_px
    with_int = split in ("test", "paper")
    if split == "paper":
        lot = load_bundled_lot()
        rng = np.random.default_rng([int(seed), 11])
        try:
            sc = generate_paper_scenario(lot, seed, True)
        except ScenarioError:
            return _empty(size)
        gen = _generator(lot, TrafficParams(t_final=es.paper_t_final))
        ego_u, ego_x = gen.plan_ego(rng, [], start_pose=sc.ego_start)
        labels = {int(v.id): int(v.target_spot_id) for v in sc.dynamic_vehicles()}
        kinds = {v: PARK for v in labels}
        t_final, code = es.paper_t_final, LOT_PAPER
    else:
        rng = np.random.default_rng([int(seed), 7])
        dlp = rng.random() < es.p_dlp
        lot = load_dlp_lot() if dlp else random_lot(seed)
        code = LOT_DLP if dlp else LOT_RANDOM
        tr = _generator(lot, TrafficParams(t_final=es.t_final)).generate(seed)
        sc, labels, kinds, ego_u, ego_x, t_final = tr.scenario, tr.labels, tr.kinds, tr.ego_controls, tr.ego_states, \
            es.t_final
    world = TrainingWorld(lot, sc, WorldConfig(t_final=t_final + 1.0 + HORIZON, sensor=SensorConfig()))
    intent = None
    if with_int:
        from avp_perception.core.intent_model import IntentPredictor

        intent = IntentPredictor.pretrained(lot, es.bev)
    rows: list[dict] = []

    def collect(k, obs, core, hist, dyn):
        if intent is not None:
            for v in dyn:
                intent.time_in_lot(obs, v)
        if k % spec.stride:
            return
        sel = [v for v in dyn if int(v.id) in labels]
        if not sel:
            return
        if intent is not None:
            its, bevs = intent.predict_all(obs, sel, core.beliefs, ego_history=hist, return_bevs=True)
        else:
            its = [None] * len(sel)
            bevs = core.intent.renderer().render_all(obs, sel, core.beliefs.b_tilde, core.beliefs.observed_mask, hist)
        for v, bev, it in zip(sel, bevs, its, strict=True):
            rows.append({"k": k, "v": v, "image": bev.image, "expl": bev.exploration_points.copy(), "it": it})

    run_episode(lot, world, labels, kinds, ego_u, ego_x, es, seed, code, t_final + HORIZON, rng,
                collect=collect)
    log = np.asarray(world.log_vehicles)  # (K + 1, N, 3) ground truth: labels only
    col = {int(v): j for j, v in enumerate(world.vehicle_ids)}
    n_h = int(round(HORIZON / world.dt))
    out = []
    for r in rows:
        k, v = r["k"], r["v"]
        if k + n_h > len(log) - 1 or int(v.id) not in col:
            continue
        track = log[k:, col[int(v.id)]]
        if np.hypot(*np.diff(track[: n_h + 1, :2], axis=0).T).max() > spec.max_jump:
            continue
        pose = np.asarray(v.pose, float)
        goal, kind = _goal(lot, labels[int(v.id)], pose, track, r["expl"], spec, world.dt)
        g, p, cv = intention_goals(r["it"], lot, 0.3) if r["it"] is not None else (
            np.zeros((MAX_GOALS, 3)), np.zeros(MAX_GOALS), 0.0)
        out.append((r["image"], np.asarray(v.history, float), track[1: n_h + 1].copy(), goal, kind, g, p, cv,
                    r["it"] is not None, (v.length, v.width), seed, code, k, int(v.id), KIND_CODES[kinds[int(v.id)]]))
    if not out:
        return _empty(size, int(round(sc.t_hist / world.dt)) + 1)
    cols = list(zip(*out, strict=True))
    hist_len = max(len(h) for h in cols[1])
    hists = np.stack([np.concatenate([np.repeat(h[:1], hist_len - len(h), axis=0), h]) for h in cols[1]])
    return TrajSamples(images=np.stack(cols[0]), history=hists, future=np.stack(cols[2]), goal=np.stack(cols[3]),
                       goal_kind=np.array(cols[4], np.int8), int_goals=np.stack(cols[5]), int_probs=np.stack(cols[6]),
                       int_cv=np.array(cols[7]), has_int=np.array(cols[8], bool), dims=np.array(cols[9], float),
                       episode=np.array(cols[10], np.int64), lot=np.array(cols[11], np.int8),
                       step=np.array(cols[12], np.int32), vehicle=np.array(cols[13], np.int64),
                       kind=np.array(cols[14], np.int8))


def _goal(lot: LotMap, target: int, pose: np.ndarray, track: np.ndarray, expl: np.ndarray, spec: TrajDataSpec,
          dt: float) -> tuple[np.ndarray, int]:
    """The goal label of one sample (module docstring): (pose (3,), kind)."""
    half = 0.5 * spec.episode.bev.extent_m
    if target >= 0 and lot.has_spot(int(target)):
        sp = lot.spot_poses[lot.spot_index(int(target))]
        loc = to_agent_frame(np.append(sp[:2], 0.0), pose)
        n = min(len(track), int(round(spec.spot_horizon / dt)) + 1)
        if abs(loc[0]) <= half and abs(loc[1]) <= half and \
                np.hypot(*(track[:n, :2] - sp[:2]).T).min() <= spec.spot_reach:
            return np.asarray(sp, float).copy(), 0
    radius = spec.episode.bev.exploration_radius
    d = np.hypot(*(track[:, :2] - pose[:2]).T)
    out = np.nonzero(d >= radius)[0]
    exit_pose = track[out[0]] if len(out) else track[-1]
    if len(expl):
        j = int(np.argmin(np.hypot(*(np.asarray(expl)[:, :2] - exit_pose[:2]).T)))
        return np.asarray(expl[j], float).copy(), 1
    return np.asarray(exit_pose, float).copy(), 2


def split_seeds(split: str, n: int) -> list[int]:
    return [TRAJ_SEED0[split] + i for i in range(int(n))]


def generate(split: str, n_episodes: int, spec: TrajDataSpec = TrajDataSpec(), workers: int = 1,
             progress: bool = True) -> TrajSamples:
    """All samples of ``n_episodes`` episodes of a split, in seed order whatever the number of workers."""
    from avp_training.dataset import _bar, _worker_init

    jobs = [(split, s, spec) for s in split_seeds(split, n_episodes)]
    bar = _bar(len(jobs), f"episodes {split}", progress)
    parts, n = [], 0
    if workers <= 1:
        it = map(_episode, jobs)
        pool = None
    else:
        pool = mp.get_context("fork").Pool(workers, initializer=_worker_init)
        it = pool.imap(_episode, jobs, chunksize=1)
    try:
        for part in it:
            parts.append(part)
            n += len(part)
            bar.update(1)
            bar.set_postfix(samples=n)
    finally:
        if pool is not None:
            pool.close()
            pool.join()
    bar.close()
    size = spec.episode.bev.size_px
    return TrajSamples.concat(parts) if parts else _empty(size)


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
    from avp_perception.core.intent_model import images_to_tensor

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

    from avp_perception.core.intent_model import default_weights_path, load_cnn

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

"""Data of the learned trajectory predictor (model card docs/trajectory_model.md).

**Data** (:func:`generate`): episodes of the intent data's traffic generator (:mod:`.traffic`) on the DLP-derived and
random lots (training, validation, held-out test by seed) and the paper's §VI-A protocol on the paper lot (test only),
run by the intent data's episode runner (:func:`.dataset.run_episode`: the observer's occlusion-aware observation, eq.
(7), the ego trail). Every ``stride`` steps each observed dynamic traffic car is a sample: its *observed* history, its
BEV I_k,0 drawn by the inference renderer from the observation-only belief (exactly what
:class:`~avp_predictors.learned_prediction.LearnedPredictor` renders), and — from ground truth, for labels only —
its future over the next 4 s from the simulator's log and its goal:

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
"""

from __future__ import annotations

import multiprocessing as mp
from dataclasses import dataclass, field, fields

import numpy as np

from avp_predictors.intention import Intention
from avp_predictors.learned_prediction import (
    MODEL_DT,
    N_FUT,
    history_poses,
    to_agent_frame,
)
from avp_predictors.prediction import BezierPredictor, PredictionConfig
from avp_scenario.scenario import ScenarioError, generate_paper_scenario
from avp_sensing.observation import SensorConfig
from avp_sim.core.world import World, WorldConfig
from avp_traffic.traffic import PARK, TrafficParams
from avp_training.dataset import (
    KIND_CODES,
    LOT_DLP,
    LOT_PAPER,
    LOT_RANDOM,
    ArrayFile,
    DataSpec,
    _generator,
    _truth_of,
    run_episode,
)
from avp_training.lots import load_dlp_lot, random_lot
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
class TrajSamples(ArrayFile):
    """One split: per sample i the BEV, the observed history, the ground-truth future and goal (world frame)."""

    FILE_KIND = "a trajectory sample file"
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


def episode_samples(args: tuple) -> TrajSamples:
    """The samples of one episode: ``(split, seed, spec)`` or ``(split, seed, spec, sensing)``. With noisy
    ``sensing`` (a preset of avp_sensing.noisy) the observer sees through it and the tracker: a sample is a track
    that follows a traffic car (:func:`avp_sensing.noisy.truth_ids`), its history the track's, its future and goal
    the car's (ground truth, labels only)."""
    split, seed, spec = args[:3]
    sensing = args[3] if len(args) > 3 else "exact"
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
    world = World(lot, sc, WorldConfig(t_final=t_final + 1.0 + HORIZON, sensor=SensorConfig()))
    intent = None
    if with_int:
        from avp_predictors.intent_model import IntentPredictor

        intent = IntentPredictor.pretrained(lot, es.bev)
    rows: list[dict] = []

    def collect(k, obs, core, hist, dyn):
        if intent is not None:
            for v in dyn:
                intent.time_in_lot(obs, v)
        if k % spec.stride:
            return
        truth = _truth_of(world, obs, sensing)
        sel = [v for v in dyn if truth(v) in labels]
        if not sel:
            return
        if intent is not None:
            its, bevs = intent.predict_all(obs, sel, core.beliefs, ego_history=hist, return_bevs=True)
        else:
            its = [None] * len(sel)
            bevs = core.intent.renderer().render_all(obs, sel, core.beliefs.b_tilde, core.beliefs.observed_mask, hist)
        for v, bev, it in zip(sel, bevs, its, strict=True):
            rows.append({"k": k, "v": v, "id": truth(v), "image": bev.image, "expl": bev.exploration_points.copy(),
                         "it": it})

    run_episode(lot, world, labels, kinds, ego_u, ego_x, es, seed, code, t_final + HORIZON, rng,
                collect=collect, sensing=sensing)
    log = np.asarray(world.log_vehicles)  # (K + 1, N, 3) ground truth: labels only
    col = {int(v): j for j, v in enumerate(world.vehicle_ids)}
    n_h = int(round(HORIZON / world.dt))
    out = []
    for r in rows:
        k, v, vid = r["k"], r["v"], r["id"]
        if k + n_h > len(log) - 1 or vid not in col:
            continue
        track = log[k:, col[vid]]
        if np.hypot(*np.diff(track[: n_h + 1, :2], axis=0).T).max() > spec.max_jump:
            continue
        pose = np.asarray(v.pose, float)
        goal, kind = _goal(lot, labels[vid], pose, track, r["expl"], spec, world.dt)
        g, p, cv = intention_goals(r["it"], lot, 0.3) if r["it"] is not None else (
            np.zeros((MAX_GOALS, 3)), np.zeros(MAX_GOALS), 0.0)
        out.append((r["image"], np.asarray(v.history, float), track[1: n_h + 1].copy(), goal, kind, g, p, cv,
                    r["it"] is not None, (v.length, v.width), seed, code, k, vid, KIND_CODES[kinds[vid]]))
    if not out:
        return _empty(size, int(round(sc.t_hist / world.dt)) + 1)
    cols = list(zip(*out, strict=True))
    # a tracked history is shorter while its track is young: every episode pads to the full t_hist (as exact does)
    hist_len = max([int(round(sc.t_hist / world.dt)) + 1] + [len(h) for h in cols[1]])
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
             progress: bool = True, sensing: str = "exact") -> TrajSamples:
    """All samples of ``n_episodes`` episodes of a split, in seed order whatever the number of workers;
    ``sensing``: the observer's sensing preset (:func:`episode_samples`)."""
    from avp_training.dataset import _bar, _worker_init

    jobs = [(split, s, spec, sensing) for s in split_seeds(split, n_episodes)]
    bar = _bar(len(jobs), f"episodes {split}", progress)
    parts, n = [], 0
    if workers <= 1:
        it = map(episode_samples, jobs)
        pool = None
    else:
        pool = mp.get_context("fork").Pool(workers, initializer=_worker_init)
        it = pool.imap(episode_samples, jobs, chunksize=1)
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

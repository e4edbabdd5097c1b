"""Intent-model samples exactly as the live pipeline sees them (docs/intent_model.md).

An episode (:class:`~.traffic.Traffic`, or the paper's §VI-A protocol for the paper-lot test set) runs in the
:class:`~avp_sim.core.world.World`. Every step the observer's observation (§III-A ray casting) goes through
the perception pipeline's own code: :meth:`PerceptionCore.ego_history`, the belief update eq. (7)
(:meth:`BeliefMap.observe`) and the time-in-lot bookkeeping of :class:`IntentPredictor`. Every ``stride``-th
step, each observed dynamic vehicle with at least one candidate spot becomes one sample (with none the
only option is "none": nothing to predict) made by :meth:`IntentPredictor.inputs`, the call
:meth:`IntentPredictor.predict_all` makes at inference: the BEV I_k,0 drawn from b~_t (unobserved spots
with b~ >= beta get default cars), the candidate spots I_can,k, their marked images I_k,i and the features.
The belief is eq. (7) only: eq. (8) would feed the model's own predictions back into later BEVs, which
needs a model (docs/intent_model.md discusses the gap).

Label: the index of the car's true spot among [none, candidates] — 0 ("none") for cars that leave or give
up, and for parkers whose spot is not a candidate (unobserved, believed occupied, covered by another car or
outside the 40 m crop).

Storage (:class:`Samples`, one ``.npz`` per split): I_k,0 as uint8, each marked image as the box where it
differs from I_k,0 (``candidate_boxes``) and those pixels, features, label and metadata. The observer (ego)
drives the random tour of :meth:`TrafficGenerator.plan_ego` and holds (v = 0) while one of its next 1.5 s
of footprints would come within 0.4 m of another car; it also stops now and then for 2-5 s. An episode ends
at t_final, when the observer collides, or after 10 s of holding.
"""

from __future__ import annotations

import multiprocessing as mp
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from avp_belief_map.bev import BEVConfig
from avp_perception.core.pipeline import PerceptionCore
from avp_predictors.intent_model import N_FEATURES, IntentPredictor
from avp_scenario.scenario import ScenarioError, generate_paper_scenario
from avp_sensing.observation import SensorConfig
from avp_sim.core.world import World, WorldConfig
from avp_traffic.traffic import LEAVE, PARK, WANDER, TrafficGenerator, TrafficParams
from avp_training.lots import load_dlp_lot, random_lot
from avp_world.geometry import rect_corners, rects_overlap
from avp_world.lot import LotMap, load_bundled_lot

KIND_CODES = {PARK: 0, LEAVE: 1, WANDER: 2}
LOT_DLP, LOT_RANDOM, LOT_PAPER = 0, 1, 2
LOT_NAMES = {LOT_DLP: "dlp_west", LOT_RANDOM: "random", LOT_PAPER: "paper_lot"}
SPLIT_SEED0 = {"train": 0, "val": 1_000_000, "test": 2_000_000, "paper": 3_000_000}


@dataclass(frozen=True)
class DataSpec:
    """How episodes become samples (module docstring)."""

    stride: int = 3  # steps between two samples of the same vehicle (0.3 s at dt = 0.1 s)
    t_final: float = 60.0  # s per training / test episode
    paper_t_final: float = 40.0  # s per paper-protocol episode (its cars park within ~25 s)
    p_dlp: float = 0.35  # share of training-distribution episodes on the DLP lot (the rest: random lots)
    hold_lookahead: int = 15  # observer steps checked ahead
    hold_margin: float = 0.4  # m
    max_hold: float = 10.0  # s of holding that end an episode
    pause_rate: float = 0.03  # 1/s: the observer starts a pause
    pause: tuple[float, float] = (2.0, 5.0)  # s
    bev: BEVConfig = field(default_factory=BEVConfig)


class ArrayFile:
    """Mixin for a dataclass of numpy arrays: one compressed .npz, a member per field. ``FILE_KIND`` names what a
    file must be (in the error for a file that is not)."""

    FILE_KIND = "a sample file"

    def save(self, path: str | Path) -> None:
        np.savez_compressed(Path(path), **{f.name: getattr(self, f.name) for f in fields(self)})

    @classmethod
    def load(cls, path: str | Path):
        """The inverse of :meth:`save`; a file missing a field is a ValueError naming it and what it is not."""
        with np.load(Path(path)) as z:
            missing = [f.name for f in fields(cls) if f.name not in z.files]
            if missing:
                raise ValueError(f"{path}: not {cls.FILE_KIND} (missing {', '.join(missing)})")
            return cls(**{f.name: z[f.name] for f in fields(cls)})


@dataclass
class Samples(ArrayFile):
    """Samples of one split. Instance i owns candidates ``cand_offsets[i]:cand_offsets[i + 1]`` and feature rows
    ``cand_offsets[i] + i : cand_offsets[i + 1] + i + 1`` (its "none" row first); candidate c's marked pixels are
    ``patch_data[patch_offsets[c]:patch_offsets[c + 1]]`` shaped by ``candidate_boxes[c]``."""

    FILE_KIND = "an intent sample file"
    images: np.ndarray  # (N, H, W, 3) uint8, I_k,0
    cand_offsets: np.ndarray  # (N + 1,) int64
    candidate_boxes: np.ndarray  # (C, 4) int64 inclusive (row0, row1, col0, col1)
    candidate_spot_ids: np.ndarray  # (C,) int64
    patch_offsets: np.ndarray  # (C + 1,) int64
    patch_data: np.ndarray  # (P,) uint8
    features: np.ndarray  # (C + N, N_FEATURES) float32
    labels: np.ndarray  # (N,) int64: 0 = none, i = candidate i
    episode: np.ndarray  # (N,) int64 episode seed
    lot: np.ndarray  # (N,) int8 LOT_* code
    step: np.ndarray  # (N,) int32
    vehicle: np.ndarray  # (N,) int64
    kind: np.ndarray  # (N,) int8 KIND_CODES
    target_spot: np.ndarray  # (N,) int64, -1 = none
    speed: np.ndarray  # (N,) float32
    pose: np.ndarray  # (N, 3) float64: V_k's pose (the crop centre)

    def __len__(self) -> int:
        return len(self.labels)

    @property
    def n_candidates(self) -> np.ndarray:
        return np.diff(self.cand_offsets)

    def feature_rows(self, i: int) -> slice:
        return slice(int(self.cand_offsets[i]) + i, int(self.cand_offsets[i + 1]) + i + 1)

    def candidate_images(self, i: int) -> np.ndarray:
        """(K, H, W, 3) the marked images I_k,1..K of instance i, rebuilt from I_k,0 and the stored boxes."""
        base = self.images[i]
        c0, c1 = int(self.cand_offsets[i]), int(self.cand_offsets[i + 1])
        out = np.repeat(base[None], c1 - c0, axis=0)
        for j, c in enumerate(range(c0, c1)):
            r0, r1, q0, q1 = (int(v) for v in self.candidate_boxes[c])
            if r1 >= r0:
                out[j, r0:r1 + 1, q0:q1 + 1] = self.patch_data[self.patch_offsets[c]:self.patch_offsets[c + 1]].reshape(
                    r1 - r0 + 1, q1 - q0 + 1, 3)
        return out

    @classmethod
    def concat(cls, parts: Sequence[Samples], size_px: int = 100) -> Samples:
        parts = [p for p in parts if len(p)]
        if not parts:
            return empty_samples(size_px)
        out = {}
        for f in fields(cls):
            arrs = [getattr(p, f.name) for p in parts]
            if f.name in ("cand_offsets", "patch_offsets"):
                acc, pieces = 0, []
                for k, a in enumerate(arrs):
                    pieces.append(a[(0 if k == 0 else 1):] + acc)
                    acc += int(a[-1])
                out[f.name] = np.concatenate(pieces)
            else:
                out[f.name] = np.concatenate(arrs)
        return cls(**out)

    def subset(self, idx: np.ndarray) -> Samples:
        """The instances ``idx`` (in that order) as a new :class:`Samples`."""
        parts = []
        for i in np.asarray(idx, dtype=np.int64):
            c0, c1 = int(self.cand_offsets[i]), int(self.cand_offsets[i + 1])
            p0, p1 = int(self.patch_offsets[c0]), int(self.patch_offsets[c1])
            parts.append(Samples(
                images=self.images[i:i + 1], cand_offsets=np.array([0, c1 - c0]),
                candidate_boxes=self.candidate_boxes[c0:c1], candidate_spot_ids=self.candidate_spot_ids[c0:c1],
                patch_offsets=self.patch_offsets[c0:c1 + 1] - p0, patch_data=self.patch_data[p0:p1],
                features=self.features[self.feature_rows(int(i))], labels=self.labels[i:i + 1],
                episode=self.episode[i:i + 1], lot=self.lot[i:i + 1], step=self.step[i:i + 1],
                vehicle=self.vehicle[i:i + 1], kind=self.kind[i:i + 1], target_spot=self.target_spot[i:i + 1],
                speed=self.speed[i:i + 1], pose=self.pose[i:i + 1]))
        return Samples.concat(parts, self.images.shape[1])


def empty_samples(size_px: int = 100) -> Samples:
    z = np.zeros(0, dtype=np.int64)
    return Samples(images=np.zeros((0, size_px, size_px, 3), np.uint8), cand_offsets=np.zeros(1, np.int64),
                   candidate_boxes=np.zeros((0, 4), np.int64), candidate_spot_ids=z,
                   patch_offsets=np.zeros(1, np.int64),
                   patch_data=np.zeros(0, np.uint8), features=np.zeros((0, N_FEATURES), np.float32), labels=z,
                   episode=z,
                   lot=np.zeros(0, np.int8), step=np.zeros(0, np.int32), vehicle=z, kind=np.zeros(0, np.int8),
                   target_spot=z, speed=np.zeros(0, np.float32), pose=np.zeros((0, 3)))


class _Builder:
    def __init__(self) -> None:
        self.rows: dict[str, list] = {f.name: [] for f in fields(Samples)}
        self.n_cand = 0
        self.n_patch = 0
        self.rows["cand_offsets"].append(np.zeros(1, np.int64))
        self.rows["patch_offsets"].append(np.zeros(1, np.int64))

    def add(self, bev, feats: np.ndarray, label: int, meta: dict) -> None:
        r = self.rows
        k = len(bev.candidate_idx)
        r["images"].append(bev.image[None])
        self.n_cand += k
        r["cand_offsets"].append(np.array([self.n_cand], np.int64))
        r["candidate_boxes"].append(bev.candidate_boxes.reshape(-1, 4).astype(np.int64))
        r["candidate_spot_ids"].append(bev.candidate_spot_ids.astype(np.int64))
        sizes = []
        for j in range(k):
            r0, r1, c0, c1 = (int(v) for v in bev.candidate_boxes[j])
            patch = bev.candidate_images[j, r0:r1 + 1, c0:c1 + 1].reshape(-1) if r1 >= r0 else np.zeros(0, np.uint8)
            r["patch_data"].append(patch)
            sizes.append(len(patch))
        r["patch_offsets"].append(self.n_patch + np.cumsum(np.array(sizes, dtype=np.int64)))
        self.n_patch += int(sum(sizes))
        r["features"].append(np.asarray(feats, np.float32))
        r["labels"].append(np.array([label], np.int64))
        for name, dtype in (("episode", np.int64), ("lot", np.int8), ("step", np.int32), ("vehicle", np.int64),
                            ("kind", np.int8), ("target_spot", np.int64), ("speed", np.float32)):
            r[name].append(np.array([meta[name]], dtype))
        r["pose"].append(np.asarray(bev.pose, float).reshape(1, 3))

    def build(self, size_px: int) -> Samples:
        if not self.rows["labels"]:
            return empty_samples(size_px)
        out = {}
        for name, arrs in self.rows.items():
            out[name] = np.concatenate(arrs) if arrs else np.zeros(0)
        out["patch_data"] = out["patch_data"].astype(np.uint8)
        return Samples(**out)


def label_index(candidate_spot_ids: np.ndarray, target_spot_id: int) -> int:
    """Index of the true spot among [none, candidates]: 1 + its position, 0 if it is not a candidate (or -1)."""
    if target_spot_id < 0:
        return 0
    hit = np.nonzero(np.asarray(candidate_spot_ids) == int(target_spot_id))[0]
    return int(hit[0]) + 1 if len(hit) else 0


def run_episode(lot: LotMap, world: World, labels: dict[int, int], kinds: dict[int, str], ego_controls: np.ndarray,
                ego_states: np.ndarray, spec: DataSpec, episode: int, lot_code: int, t_final: float,
                rng: np.random.Generator, stop_when_parked: bool = False, builder: _Builder | None = None,
                collect=None, sensing: str = "exact") -> _Builder:
    """Run one episode and collect its samples (module docstring). ``collect(k, obs, core, ego_history, dynamic)``,
    when given, is called every step instead of the intent sampling (the data of :mod:`.trajectory_data`).
    ``sensing``: the observer sees through the sensing model of that preset and the tracker (docs/perception.md);
    a track's label is that of the vehicle it follows (:func:`avp_sensing.noisy.truth_ids`, scoring only), and
    a track that follows none is not sampled."""
    b = builder if builder is not None else _Builder()
    intent = IntentPredictor(lot, spec.bev, seed=0)  # weights unused: only inputs() is called
    core = PerceptionCore(lot, spec.bev, intent=intent, t_hist=world.scenario.t_hist)
    dt = world.dt
    ego_len, ego_wid = world.scenario.ego.length, world.scenario.ego.width
    i_plan, held, pause_left = 0, 0, 0
    n_steps = int(round(t_final / dt))
    agent_rows = {int(v): k for k, v in enumerate(world.vehicle_ids)}
    observe = noisy_observer(lot, world, sensing, episode)
    for k in range(n_steps + 1):
        obs = observe()
        truth = _truth_of(world, obs, sensing)
        hist = core.ego_history(obs)
        core.beliefs.observe(obs.vacant_spot_ids, obs.occupied_spot_ids)  # eq. (7)
        dyn = [v for v in obs.vehicles if not v.is_static]
        for v in dyn:
            intent.time_in_lot(obs, v)
        if collect is not None:
            collect(k, obs, core, hist, dyn)
        elif k % spec.stride == 0:
            sel = [v for v in dyn if truth(v) in labels]
            if sel:
                bevs, feats = intent.inputs(obs, sel, core.beliefs, ego_history=hist)
                for v, bev, f in zip(sel, bevs, feats, strict=True):
                    if len(bev.candidate_idx) == 0:
                        continue  # "none" is the only option: nothing to predict
                    target = labels[truth(v)]
                    b.add(bev, f, label_index(bev.candidate_spot_ids, target), {
                        "episode": episode, "lot": lot_code, "step": k, "vehicle": truth(v),
                        "kind": KIND_CODES[kinds[truth(v)]], "target_spot": target, "speed": bev.speed})
        if k == n_steps:
            break
        if stop_when_parked and all(_parked(world, agent_rows[v]) for v in labels):
            break
        # the observer: follow its tour, hold while blocked, pause now and then
        u = np.zeros(2)
        if pause_left > 0:
            pause_left -= 1
        elif i_plan < len(ego_controls):
            if rng.random() < spec.pause_rate * dt:
                pause_left = int(round(rng.uniform(*spec.pause) / dt))
            else:
                ahead = ego_states[i_plan + 1: i_plan + 1 + spec.hold_lookahead: 3]
                blocked = False
                if len(ahead):
                    fp = rect_corners(ahead, ego_len, ego_wid)
                    vc = world.vehicle_corners()
                    near = np.hypot(*(world.states[:, :2] - ahead[0, :2]).T) < 12.0
                    if near.any():
                        blocked = bool(rects_overlap(fp[:, None], vc[near][None], spec.hold_margin).any())
                if blocked:
                    held += 1
                    if held * dt > spec.max_hold:
                        break
                else:
                    held = 0
                    u = ego_controls[i_plan]
                    i_plan += 1
        world.step(float(u[0]), float(u[1]))
        if world.done:
            break
    return b


def noisy_observer(lot: LotMap, world: World, sensing: str, seed: int):
    """``world.observe`` (``sensing`` exact), or the observation through the sensing preset ``sensing`` and the
    tracker (avp_sensing.noisy, avp_tracking), seeded by ``seed``."""
    if sensing == "exact":
        return world.observe
    from avp_sensing.noisy import PRESETS, NoisySensor
    from avp_tracking.core.perceive import TrackingPerception
    from avp_tracking.core.tracker import Tracker, TrackerConfig

    if sensing not in PRESETS:
        raise ValueError(f"sensing: expected one of {sorted(PRESETS)}, got {sensing!r}")
    sensor = NoisySensor(PRESETS[sensing], seed, float(world.caster.region_range.max()))
    perception = TrackingPerception(lot, Tracker(TrackerConfig(history_steps=world.hist + 1)))
    return lambda: perception.observe(sensor.sense(world))


def _truth_of(world: World, obs, sensing: str):
    """The simulator id an observed vehicle is, for labels only: its own id with exact sensing, else the id of the
    vehicle its track follows (-1: none)."""
    if sensing == "exact":
        return lambda v: int(v.id)
    from avp_sensing.noisy import truth_ids

    ids = truth_ids(world, obs)
    return lambda v: ids.get(int(v.id), -1)


def _parked(world: World, row: int) -> bool:
    occupied, vehicle_spot = world.occupancy()
    return bool(vehicle_spot[row] >= 0)


# ------------------------------------------------------------------------------------------ episodes


_GENERATORS: dict[str, TrafficGenerator] = {}


def _generator(lot: LotMap, params: TrafficParams) -> TrafficGenerator:
    key = f"{lot.name}:{lot.source}:{params}"
    if key not in _GENERATORS:
        if len(_GENERATORS) > 8:
            _GENERATORS.clear()
        _GENERATORS[key] = TrafficGenerator(lot, params)
    return _GENERATORS[key]


def episode_lot(seed: int, spec: DataSpec, rng: np.random.Generator, lot_choice: str = "mixed"
                ) -> tuple[LotMap, int]:
    """The lot of a training-distribution episode and its LOT_* code; "mixed" draws DLP (``p_dlp``) or this seed's
    random lot from ``rng`` (the episode's own generator, seeded [seed, 7])."""
    if lot_choice == "mixed":
        lot_choice = "dlp" if rng.random() < spec.p_dlp else "random"
    lot = {"dlp": load_dlp_lot, "paper": load_bundled_lot}.get(lot_choice, lambda: random_lot(seed))()
    return lot, {"dlp": LOT_DLP, "paper": LOT_PAPER}.get(lot_choice, LOT_RANDOM)


def traffic_episode(seed: int, spec: DataSpec, lot_choice: str = "mixed", sensing: str = "exact") -> Samples:
    """Samples of one training-distribution episode: the DLP lot (probability ``p_dlp``) or the random lot of
    this seed (``lot_choice``: "mixed", "dlp", "random" or "paper" for the paper lot with this traffic)."""
    rng = np.random.default_rng([int(seed), 7])
    lot, code = episode_lot(seed, spec, rng, lot_choice)
    gen = _generator(lot, TrafficParams(t_final=spec.t_final))
    tr = gen.generate(seed)
    world = World(lot, tr.scenario, WorldConfig(t_final=spec.t_final + 1.0, sensor=SensorConfig()))
    b = run_episode(lot, world, tr.labels, tr.kinds, tr.ego_controls, tr.ego_states, spec, seed, code, spec.t_final,
                    rng, sensing=sensing)
    return b.build(spec.bev.size_px)


def paper_episode(seed: int, spec: DataSpec, sensing: str = "exact") -> Samples:
    """Samples of one episode of the paper's §VI-A protocol on the paper lot (1-2 cars parking in the contested
    bottom spots, reactive), seen by the observer starting at the paper's ego start and touring the lanes."""
    lot = load_bundled_lot()
    rng = np.random.default_rng([int(seed), 11])
    try:
        sc = generate_paper_scenario(lot, seed, True)
    except ScenarioError:
        return empty_samples(spec.bev.size_px)
    gen = _generator(lot, TrafficParams(t_final=spec.paper_t_final))
    ego_u, ego_x = gen.plan_ego(rng, [], start_pose=sc.ego_start)
    labels = {int(v.id): int(v.target_spot_id) for v in sc.dynamic_vehicles()}
    kinds = {v: PARK for v in labels}
    world = World(lot, sc, WorldConfig(t_final=spec.paper_t_final + 1.0, sensor=SensorConfig()))
    b = run_episode(lot, world, labels, kinds, ego_u, ego_x, spec, seed, LOT_PAPER, spec.paper_t_final, rng,
                    stop_when_parked=True, sensing=sensing)
    return b.build(spec.bev.size_px)


def _episode_job(args: tuple[str, int, DataSpec, str]) -> Samples:
    split, seed, spec, sensing = args
    if split == "paper":
        return paper_episode(seed, spec, sensing)
    return traffic_episode(seed, spec, sensing=sensing)


def episode_seeds(split: str, n: int) -> list[int]:
    """The episode seeds of a split: disjoint ranges, so held-out splits never share an episode with training."""
    return [SPLIT_SEED0[split] + i for i in range(int(n))]


def generate_split(split: str, n_episodes: int, spec: DataSpec = DataSpec(), workers: int = 1,
                   progress: bool = True, seeds: Iterable[int] | None = None, sensing: str = "exact") -> Samples:
    """All samples of ``n_episodes`` episodes of a split ("train", "val", "test": DLP and random lots;
    "paper": the paper's protocol on the paper lot), in seed order whatever the number of workers; ``sensing``: the
    observer's sensing preset (:func:`noisy_observer`)."""
    seeds = list(seeds) if seeds is not None else episode_seeds(split, n_episodes)
    jobs = [(split, s, spec, sensing) for s in seeds]
    bar = _bar(len(jobs), f"episodes {split}", progress)
    parts: list[Samples] = []
    n = 0
    if workers <= 1:
        for job in jobs:
            parts.append(_episode_job(job))
            n += len(parts[-1])
            bar.update(1)
            bar.set_postfix(samples=n)
    else:
        with mp.get_context("fork").Pool(workers, initializer=_worker_init) as pool:
            for part in pool.imap(_episode_job, jobs, chunksize=1):
                parts.append(part)
                n += len(part)
                bar.update(1)
                bar.set_postfix(samples=n)
    bar.close()
    return Samples.concat(parts, spec.bev.size_px)


def _worker_init() -> None:
    import torch

    torch.set_num_threads(1)


def _bar(total: int, desc: str, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, disable=not enabled, dynamic_ncols=True, mininterval=1.0)

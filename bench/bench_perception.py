#!/usr/bin/env python3
"""Benchmark of the perception core (paper §V-A..C) on observation snapshots of seeded scenarios.

Snapshots: the §VI-A generator with exactly 1 or 2 dynamic vehicles and the ego parked at the lot centre
(21.5, 20) facing south (from the paper's start at the top of the lot the ego sees the second dynamic
vehicle too rarely); every ``--stride``-th step of each episode where the ego observes exactly that many
dynamic vehicles is kept. Timed per snapshot:

* step = belief update eq. (7) + BEV reconstruction of every observed dynamic vehicle (all candidate
  images) + intent CNN on all candidates of all vehicles in one batch (the shipped weights, as the node
  loads them; torch.inference_mode) + eq. (8); target: median <= 5 ms; reported per thread count of
  ``torch.set_num_threads`` (the belief node uses 1);
* Bezier prediction (§V-C) of the 2-vehicle snapshots with 2 intentions >= mu per vehicle; target <= 1 ms;
* Hybrid A* prediction (``make_predictor("hybrid_astar")``) of the same snapshots: with the Bezier
  bench's intentions (the first two vacant spots of the observation, often across the lot) and with the two
  vacant spots nearest to each vehicle; per step, plus searches, paths found, iterations and static worlds
  built; also on consecutive steps (stride 1) of the same episodes, where the static-world cache works as in
  the node (the strided snapshots jump between episodes and goal sets).

Usage: python bench/bench_perception.py [--snapshots 150] [--repeats 3] [--threads 1 2] [--sweep]
``--sweep`` also times the other input resolutions (400 px at 0.1 m/px as ParkPredict+, 200 @ 0.2, 80 @ 0.5)
and the plain-torch / fused inference paths.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import time
from dataclasses import replace

import cv2
import numpy as np
import torch

from avp_belief_map.belief import BeliefMap
from avp_belief_map.bev import BEVConfig, BEVRenderer
from avp_perception.core.pipeline import make_intent_predictor
from avp_predictors.intent_model import IntentPredictor, SmallRegularizedCNN
from avp_predictors.intention import Intention
from avp_predictors.prediction import BezierPredictor
from avp_scenario.scenario import ScenarioError, ScenarioParams, generate_paper_scenario
from avp_sim.core.world import World
from avp_world.lot import load_bundled_lot


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return (f"{cpu}, {os.cpu_count()} logical CPUs; Python {platform.python_version()}, torch {torch.__version__}, "
            f"numpy {np.__version__}, opencv {cv2.__version__}")


def snapshots(lot, n_dynamic: int, count: int, stride: int, max_steps: int = 200):
    params = replace(ScenarioParams(), ego_start=(21.5, 20.0, -math.pi / 2), n_dynamic=(n_dynamic, n_dynamic))
    out = []
    seed = 0
    while len(out) < count and seed < 500:
        try:
            world = World(lot, generate_paper_scenario(lot, seed, True, params))
        except ScenarioError:
            seed += 1
            continue
        seed += 1
        while not world.done and world.step_index < max_steps and len(out) < count:
            if world.step_index % stride == 0:
                obs = world.observe()
                if sum(not v.is_static for v in obs.vehicles) == n_dynamic:
                    out.append(obs)
            world.step(0.0, 0.0)
    return out


def perception_step(obs, beliefs: BeliefMap, intent: IntentPredictor):
    beliefs.reset()
    beliefs.observe(obs.vacant_spot_ids, obs.occupied_spot_ids)  # eq. (7)
    dyn = [v for v in obs.vehicles if not v.is_static]
    intentions = intent.predict_all(obs, dyn, beliefs)  # BEV + CNN
    beliefs.apply_intentions(intentions)  # eq. (8)
    return intentions


def time_steps(obs_list, lot, cfg: BEVConfig, mode: str, repeats: int) -> np.ndarray:
    if cfg.size_px == BEVConfig().size_px:
        intent, _ = make_intent_predictor(lot, cfg, mode=mode)  # the shipped weights (the node's default)
    else:  # --sweep: no weights of this size; seeded random ones reading as many features (values do not matter)
        n = make_intent_predictor(lot, BEVConfig())[0].net.n_features
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(0)
            model = SmallRegularizedCNN(cfg.size_px, n_features=n)
        intent = IntentPredictor(lot, cfg, model=model, mode=mode)
    beliefs = BeliefMap.from_lot(lot)
    for obs in obs_list[:10]:  # warm-up
        perception_step(obs, beliefs, intent)
    times = []
    for _ in range(repeats):
        for obs in obs_list:
            t0 = time.perf_counter()
            perception_step(obs, beliefs, intent)
            times.append(time.perf_counter() - t0)
    return np.array(times) * 1e3


def time_bev(obs_list, lot, cfg: BEVConfig) -> tuple[np.ndarray, float]:
    renderer = BEVRenderer(lot, cfg)
    beliefs = BeliefMap.from_lot(lot)
    times, cands = [], []
    for obs in obs_list:
        beliefs.reset()
        bt = beliefs.observe(obs.vacant_spot_ids, obs.occupied_spot_ids)
        dyn = [v for v in obs.vehicles if not v.is_static]
        t0 = time.perf_counter()
        bevs = [renderer.render(obs, v, bt, beliefs.observed_mask) for v in dyn]
        times.append(time.perf_counter() - t0)
        cands.append(sum(len(b.candidate_spot_ids) + 1 for b in bevs))
    return np.array(times) * 1e3, float(np.mean(cands))


def bezier_intentions(obs, lot):
    """Two spot intentions >= mu (0.45, 0.35) and the rest on 'none' for every dynamic vehicle."""
    vacant = list(obs.vacant_spot_ids)
    out = []
    for v in obs.vehicles:
        if v.is_static:
            continue
        ids = np.array((vacant + [0, 1])[:2], dtype=np.int64)
        out.append(Intention(int(v.id), ids, np.array([0.45, 0.35]), none_probability=0.2))
    return out


def nearest_intentions(obs, lot):
    """The two vacant spots nearest to each dynamic vehicle at 0.5 and 0.35, 'none' 0.15."""
    vacant = np.asarray(obs.vacant_spot_ids, dtype=np.int64)
    out = []
    for v in obs.vehicles:
        if v.is_static or len(vacant) < 2:
            continue
        d = np.hypot(*(lot.spot_poses[[lot.spot_index(s) for s in vacant], :2] - v.pose[:2]).T)
        out.append(Intention(int(v.id), vacant[np.argsort(d, kind="stable")[:2]], np.array([0.5, 0.35]),
                             none_probability=0.15))
    return out


def stats(ms: np.ndarray) -> str:
    return (f"median {np.median(ms):.2f} ms, p90 {np.percentile(ms, 90):.2f} ms, mean {ms.mean():.2f} ms "
            f"(n = {len(ms)})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--snapshots", type=int, default=150, help="snapshots per dynamic-vehicle count")
    ap.add_argument("--repeats", type=int, default=3, help="timed passes over the snapshots")
    ap.add_argument("--stride", type=int, default=5, help="keep every stride-th step of an episode")
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="torch.set_num_threads values")
    ap.add_argument("--sweep", action="store_true", help="also time other resolutions and inference paths")
    args = ap.parse_args()

    lot = load_bundled_lot("paper_lot")
    print(f"machine: {machine()}; load average (1, 5, 15 min) {os.getloadavg()}")
    sets = {k: snapshots(lot, k, args.snapshots, args.stride) for k in (1, 2)}
    cfg = BEVConfig()
    print(make_intent_predictor(lot, cfg)[1])
    print(f"lot '{lot.name}' ({lot.n_spots} spots); BEV {cfg.size_px} x {cfg.size_px} px at {cfg.m_per_px} m/px "
          f"({cfg.extent_m:.0f} m square); snapshots: " + ", ".join(
              f"{len(v)} with {k} dynamic vehicle(s)" for k, v in sets.items()))
    for k, obs_list in sets.items():
        bev_ms, cands = time_bev(obs_list, lot, cfg)
        print(f"[{k} dyn] BEV reconstruction only: {stats(bev_ms)}; CNN inputs per step {cands:.1f} "
              f"(candidates + 'none')")

    best: dict[int, tuple[float, int]] = {}
    medians: dict[tuple[int, int], float] = {}
    for th in args.threads:
        torch.set_num_threads(th)
        for k, obs_list in sets.items():
            ms = time_steps(obs_list, lot, cfg, "incremental", args.repeats)
            print(f"[{k} dyn] threads {th}: belief (7) + BEV + CNN + belief (8): {stats(ms)}")
            medians[(k, th)] = float(np.median(ms))
            if k not in best or np.median(ms) < best[k][0]:
                best[k] = (float(np.median(ms)), th)
    print(f"load average (1, 5, 15 min) after the timed runs: {os.getloadavg()}")
    if any(m > 3.0 * best[k][0] for (k, _), m in medians.items()):
        print("note: a thread count far slower than the best one means other processes share these cores; torch's "
              "worker threads then wait for each other at every op (use 1 thread on a shared machine)")
    for k, (med, th) in best.items():
        verdict = "OK" if med <= 5.0 else "over"
        print(f"[{k} dyn] best: {med:.2f} ms median with torch.set_num_threads({th}) (target <= 5 ms: {verdict})")

    # Bezier prediction, 2 dynamic vehicles, 2 intentions >= mu each (4 curves), 4 s at dt = 0.1
    pred = BezierPredictor(lot)
    work = [(obs, bezier_intentions(obs, lot)) for obs in sets[2]]
    for obs, its in work[:10]:
        pred.predict(obs, its)
    times = []
    n_curves = 0
    for _ in range(args.repeats):
        for obs, its in work:
            t0 = time.perf_counter()
            trajs = pred.predict(obs, its)
            times.append(time.perf_counter() - t0)
            n_curves = len(trajs)
    ms = np.array(times) * 1e3
    verdict = "OK" if np.median(ms) <= 1.0 else "over"
    print(f"[2 dyn] Bezier prediction ({n_curves} trajectories x {len(trajs[0].poses)} poses): {stats(ms)} "
          f"(target <= 1 ms: {verdict})")

    # Hybrid A* prediction: the same snapshots, with those intentions and with the nearest spots
    from avp_predictors.prediction import make_predictor

    consecutive = snapshots(lot, 2, args.snapshots, 1)  # stride 1: the static-world cache works as in an episode
    for label, make, obs_set in (("Bezier bench's intentions", bezier_intentions, sets[2]),
                                 ("two nearest vacant spots", nearest_intentions, sets[2]),
                                 ("two nearest vacant spots, consecutive steps", nearest_intentions, consecutive)):
        t0 = time.perf_counter()
        pred = make_predictor("hybrid_astar", lot)
        t_init = time.perf_counter() - t0
        work = [(obs, make(obs, lot)) for obs in obs_set]
        times, totals = [], {"queries": 0, "paths": 0, "iterations": 0, "worlds_built": 0}
        for _ in range(args.repeats):
            pred = make_predictor("hybrid_astar", lot)  # fresh caches each pass (a pass replays the same steps)
            for obs, its in work:
                t0 = time.perf_counter()
                pred.predict(obs, its)
                times.append(time.perf_counter() - t0)
                for key in totals:
                    totals[key] += pred.last_stats.get(key, 0)
        ms = np.array(times) * 1e3
        q = max(totals["queries"], 1)
        print(f"[2 dyn] Hybrid A* prediction ({label}): {stats(ms)}, max {ms.max():.2f} ms; {totals['queries']} "
              f"searches, {100.0 * totals['paths'] / q:.1f} % found a path, {totals['iterations'] / q:.0f} iterations "
              f"per search, {totals['worlds_built']} static worlds built in {len(ms)} steps; predictor set-up "
              f"{t_init * 1e3:.0f} ms (Reeds-Shepp table, once per process)")

    if args.sweep:
        th = best[2][1]
        torch.set_num_threads(th)
        print(f"sweep (threads {th}, 2-vehicle snapshots, {min(40, len(sets[2]))} of them, 1 pass):")
        sub = sets[2][:40]
        for size, res in ((400, 0.1), (200, 0.2), (100, 0.4), (80, 0.5)):
            c = BEVConfig(size_px=size, m_per_px=res)
            modes = ("reference", "fused", "incremental") if size <= 100 else ("fused", "incremental")
            for mode in modes:
                ms = time_steps(sub, lot, c, mode, 1)
                print(f"  {size:>3} px @ {res} m/px, {mode:<11}: {stats(ms)}")


if __name__ == "__main__":
    main()

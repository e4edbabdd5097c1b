#!/usr/bin/env python3
"""Benchmark of the learned trajectory predictor: 2 observed dynamic vehicles x 3 intentions >= mu.

Snapshots as bench/bench_perception.py (the §VI-A generator with exactly 2 dynamic vehicles, the ego parked at the
lot centre). Per snapshot every vehicle gets 3 intentions of probability >= mu = 0.3: its nearest vacant spot
(0.34) and two exploration points 11.5 m ahead and behind it along its heading (0.33 each). Timed: one
``LearnedPredictor.predict`` call (what the prediction node runs per step) = eq. (7) on the predictor's own
belief, the BEVs I_k,0 of both vehicles, the conv stack + encoder once per vehicle, the autoregressive decoder
(10 steps) batched over the 6 (vehicle, intention) pairs, resampling to dt over 4 s. The Bezier predictor on the
same inputs is timed beside it. torch threads: 1 (``--threads`` to change). Target: median <= 20 ms.

Weights: the shipped ones if present, else seeded random weights (same cost).

Usage: python bench/bench_learned.py [--snapshots 150] [--repeats 3] [--threads 1]
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_perception import machine, snapshots, stats  # noqa: E402

from avp_predictors.intention import Intention  # noqa: E402
from avp_predictors.prediction import BezierPredictor, PredictionConfig, make_predictor  # noqa: E402
from avp_world.lot import load_bundled_lot  # noqa: E402


def three_intentions(obs, lot) -> list[Intention]:
    vacant = np.asarray(obs.vacant_spot_ids, dtype=np.int64)
    if len(vacant) == 0:
        vacant = np.asarray(lot.spot_ids[:1], dtype=np.int64)
    out = []
    for v in obs.vehicles:
        if v.is_static:
            continue
        d = np.hypot(*(lot.spot_poses[[lot.spot_index(s) for s in vacant], :2] - v.pose[:2]).T)
        spot = vacant[int(np.argmin(d))]
        x, y, th = (float(c) for c in v.pose)
        pts = np.array([[x + 11.5 * math.cos(th), y + 11.5 * math.sin(th), th],
                        [x - 11.5 * math.cos(th), y - 11.5 * math.sin(th), th + math.pi]])
        out.append(Intention(int(v.id), np.array([spot]), np.array([0.34]), exploration_points=pts,
                             exploration_probabilities=np.array([0.33, 0.33]), none_probability=0.66))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--snapshots", type=int, default=150)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--stride", type=int, default=5)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    lot = load_bundled_lot("paper_lot")
    print(f"machine: {machine()}; load average (1, 5, 15 min) {os.getloadavg()}")
    obs_list = snapshots(lot, 2, args.snapshots, args.stride)
    work = [(o, three_intentions(o, lot)) for o in obs_list]
    learned = make_predictor("learned", lot, PredictionConfig())
    torch.set_num_threads(args.threads)  # the predictor sets learned.threads (1) at start-up
    print(f"{learned.info}; torch threads {torch.get_num_threads()}; {len(work)} snapshots x {args.repeats}")
    bezier = BezierPredictor(lot)
    for name, pred in (("learned", learned), ("bezier", bezier)):
        ms = []
        n_traj = 0
        for _ in range(args.repeats):
            for o, its in work:
                if hasattr(pred, "reset"):
                    pred.reset()
                t0 = time.perf_counter()
                out = pred.predict(o, its)
                ms.append(1e3 * (time.perf_counter() - t0))
                n_traj = max(n_traj, len(out))
        print(f"[2 dyn x 3 intentions] {name} ({n_traj} trajectories x 40 poses): {stats(np.asarray(ms))}")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Tracker quality against the simulator's truth (the truth used only for scoring), per sensing model and lot.

Each episode runs the simulator core with the scripted stand-in ego (it drives the lot's lanes; no planner, so the
figures do not depend on a method), the sensing model and the tracker (avp_episode.sensing). At every step the
tracks the ego receives are scored against the vehicles the rays touch at that step (what an exact sensor reports):
a track and a vehicle match within 1 m. py-motmetrics (an independent scorer; our own distance matrix, since its
``norm2squared_matrix`` uses ``np.asfarray``, gone in NumPy 2) gives MOTA, IDF1 and the id switches; we add the id
switches per track-minute (of matched vehicle time), the position and heading RMSE of the matched pairs (the
least-cost pairing within 1 m of each step; heading wrapped to +-180 degrees, so an unresolved flip counts in full)
and the tracker's time per step.

Usage:
    python bench/bench_tracking.py [--models exact,realistic,harsh] [--seeds 0-9] [--steps 300]
        [--lots paper,dlp] [--json out/bench_tracking.json]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from bench_closed_loop import _seeds  # the seed lists "0-4" or "1,3,7", as that bench reads them

ROOT = Path(__file__).resolve().parents[1]
LOTS = {"paper": ("", "paper"), "dlp": (str(ROOT / "src/avp_world/avp_world/maps/dlp_lot.yaml"), "busy")}


def run_episode(lot, sim: dict, seed: int, steps: int, acc, errs: dict) -> None:
    """One scripted-ego episode scored into the motmetrics accumulator ``acc`` and the error lists ``errs``."""
    from scipy.optimize import linear_sum_assignment

    from avp_episode.sensing import sensed_observer
    from avp_planner.scripted_driver import ScriptedDriver
    from avp_sim.core.factory import make_world

    world = make_world(lot, sim, seed, True)
    noisy = sensed_observer(world, sim, seed)
    driver = ScriptedDriver(lot)
    for _ in range(steps):
        if world.done:
            break
        if noisy is None:
            obs = world.observe()
        else:
            frame = noisy.sensor.sense(world)
            t0 = time.perf_counter()
            obs = noisy.perception.observe(frame)
            errs["track_s"].append(time.perf_counter() - t0)
        seen = np.nonzero(world.last_scan.seen_vehicles[:len(world.states)])[0]
        gt_ids = [int(world.vehicle_ids[j]) for j in seen]
        truth = world.states[seen]
        hyp = [v for v in obs.vehicles if int(v.id) < 10**6]  # (other egos' ids are >= EGO_ID_BASE)
        est = np.array([v.history[-1] for v in hyp]).reshape(-1, 3)
        d = np.full((len(gt_ids), len(hyp)), np.nan)
        if len(gt_ids) and len(hyp):
            dist = np.hypot(truth[:, None, 0] - est[None, :, 0], truth[:, None, 1] - est[None, :, 1])
            d = np.where(dist < 1.0, dist * dist, np.nan)
        acc.update(gt_ids, [int(v.id) for v in hyp], d)
        if len(gt_ids) and len(hyp):  # the errors of the matched pairs (the least-cost pairing within 1 m)
            rows, cols = linear_sum_assignment(np.where(np.isnan(d), 1e9, d))
            for g, h in zip(rows, cols, strict=True):
                if not np.isnan(d[g, h]):
                    errs["pos"].append(math.hypot(*(truth[g, :2] - est[h, :2])))
                    errs["head"].append(math.remainder(est[h, 2] - truth[g, 2], 2 * math.pi))
        world.step(*driver.command(obs))


def score(lot_name: str, model: str, seeds: list[int], steps: int) -> dict:
    import motmetrics as mm

    from avp_episode.run_config import RunConfig, sim_values
    from avp_sim.core.factory import load_lot_param

    lot_file, family = LOTS[lot_name]
    over = {"sensing.model": model, "scenario.family": family}
    if lot_file:
        over["lot_file"] = lot_file
    sim = sim_values(RunConfig(sim_overrides=over))
    lot = load_lot_param(sim["lot_file"])
    accs, errs = [], {"pos": [], "head": [], "track_s": []}
    for seed in seeds:
        acc = mm.MOTAccumulator(auto_id=True)
        run_episode(lot, sim, seed, steps, acc, errs)
        accs.append(acc)
    mh = mm.metrics.create()
    s = mh.compute_many(accs, metrics=["mota", "idf1", "num_switches", "num_matches", "num_false_positives",
                                       "num_misses"], generate_overall=True).loc["OVERALL"]
    matched_minutes = (s["num_matches"] + s["num_switches"]) * sim["dt"] / 60.0
    t = np.asarray(errs["track_s"]) * 1e3
    return {"lot": lot_name, "model": model, "episodes": len(seeds), "steps": steps,
            "mota": round(float(s["mota"]), 3), "idf1": round(float(s["idf1"]), 3),
            "id_switches": int(s["num_switches"]),
            "switches_per_track_minute": round(float(s["num_switches"]) / max(matched_minutes, 1e-9), 3),
            "false_positives": int(s["num_false_positives"]), "misses": int(s["num_misses"]),
            "position_rmse_m": round(float(np.sqrt(np.mean(np.square(errs["pos"])))), 3) if errs["pos"] else None,
            "heading_rmse_deg": round(float(np.degrees(np.sqrt(np.mean(np.square(errs["head"]))))), 2)
            if errs["head"] else None,
            "track_median_ms": round(float(np.median(t)), 2) if len(t) else 0.0,
            "track_p95_ms": round(float(np.percentile(t, 95)), 2) if len(t) else 0.0}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--models", default="exact,realistic,harsh")
    ap.add_argument("--lots", default="paper,dlp")
    ap.add_argument("--seeds", default="0-9")
    ap.add_argument("--steps", type=int, default=300, help="steps per episode at most (dt 0.1 s)")
    ap.add_argument("--json", default="")
    args = ap.parse_args()
    rows = []
    print("| lot | sensing | episodes | MOTA | IDF1 | id switches | per track-minute | false pos. | misses | "
          "position RMSE (m) | heading RMSE (deg) | tracker ms median / p95 |")
    print("|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|")
    for lot_name in args.lots.split(","):
        for model in args.models.split(","):
            r = score(lot_name, model, _seeds(args.seeds), args.steps)
            rows.append(r)
            print(f"| {lot_name} | {model} | {r['episodes']} | {r['mota']} | {r['idf1']} | {r['id_switches']} | "
                  f"{r['switches_per_track_minute']} | {r['false_positives']} | {r['misses']} | "
                  f"{r['position_rmse_m']} | {r['heading_rmse_deg']} | {r['track_median_ms']} / "
                  f"{r['track_p95_ms']} |", flush=True)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({"args": vars(args), "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

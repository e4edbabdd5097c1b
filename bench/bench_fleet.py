#!/usr/bin/env python3
"""In-process step time of a lot with K egos (docs/world.md, "Several egos"): the simulator core and K pipelines
(:class:`MethodEgo` each: the belief node's core with the intent CNN, the prediction, the planner, wall-clock caps as
in the live graph) on one thread. Per step it times the **lot step**: every driving ego's observation (ray-cast from
its own pose) and pipeline, and the simulator's step of all of them. ``--ego-workers 2`` spreads the pipelines over two
processes (:mod:`avp_episode.ego_pool`); the simulator stays in this one. Printed: median and p95 per K, with the
episodes' outcomes and the machine's load; K = 1 in the same run is the reference.

Usage:
    python bench/bench_fleet.py --lot src/avp_world/avp_world/maps/dlp_lot.yaml --scenario busy --egos 1,8 \\
        [--method bezier] [--seeds 0-2] [--t-final 60] [--entry-interval 5] [--ego-workers 2] \\
        [--torch-threads 1] [--json out/bench_fleet.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
from bench_closed_loop import _seeds  # noqa: E402  (bench/ is the script's directory: one seed-range parser)


def run_episode(lot, sim: dict, profile, seed: int, k: int, ego_workers: int = 1) -> tuple[dict, list[float]]:
    """One episode of ``k`` egos of ``profile``: (outcome, per-step wall seconds of the lot step). ``ego_workers``
    > 1: the pipelines in that many processes (:class:`avp_episode.ego_pool.EgoPool`), started before the clock."""
    from avp_episode.ego import MethodEgo
    from avp_episode.ego_pool import EgoPool
    from avp_planner.core.ego_yield import beacon_of, with_beacons
    from avp_sim.core.factory import make_world

    world = make_world(lot, dict(sim, **{"egos.count": k}), seed, True)
    pool = EgoPool(lot, [profile] * k, workers=ego_workers, deterministic=False) if ego_workers > 1 else None
    egos = [] if pool else [MethodEgo(lot, profile, deterministic=False) for _ in range(k)]
    times: list[float] = []
    beacons: list = []  # the V2V channel, as avp_episode.fleet hands it over (decision.ego_yield reads it)
    try:
        while not world.done:
            t0 = time.perf_counter()
            driving = world.egos.driving.copy()
            obs = {i: with_beacons(world.observe(i), beacons, i) for i in range(k) if driving[i]}
            if pool is not None:
                steps = pool.step(list(obs), lambda i, obs=obs: (obs[i], None))
            else:
                steps = {i: egos[i].step(o) for i, o in obs.items()}
            cmds = [steps[i].command if i in steps else (0.0, 0.0) for i in range(k)]
            beacons = [beacon_of(i, obs[i].ego_pose, s.decision) for i, s in steps.items() if s.decision is not None]
            world.step_all(cmds)
            times.append(time.perf_counter() - t0)
    finally:
        if pool is not None:
            pool.close()
    outcome = {"seed": seed, "egos": k, "status": world.status, "steps": world.step_index,
               "parked": int(sum(s == "success" for s in world.egos.status)),
               "collisions": int(sum(s == "collision" for s in world.egos.status)),
               "moving_vehicles": int(world.is_dynamic.sum()), "pedestrians": len(world.ped_pos)}
    return outcome, times


def _torch_threads() -> int:
    import torch

    return torch.get_num_threads()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lot", default="")
    ap.add_argument("--scenario", default="paper", choices=("paper", "busy"))
    ap.add_argument("--egos", default="1,8", help="comma-separated K values")
    ap.add_argument("--method", default="bezier")
    ap.add_argument("--seeds", default="0-2", help="a-b or comma-separated")
    ap.add_argument("--t-final", type=float, default=60.0)
    ap.add_argument("--entry-interval", type=float, default=5.0, help="egos.entry_interval [s]")
    ap.add_argument("--ego-workers", type=int, default=1, help="processes the K pipelines are spread over "
                    "(avp_episode.ego_pool; 1: one thread, one after the other) [1]")
    ap.add_argument("--torch-threads", type=int, default=0, help="torch's intra-op threads for the intent CNN (0: "
                    "torch's default, one per core; the experiment's workers use 1) [0]")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    if args.torch_threads > 0:
        import torch

        torch.set_num_threads(args.torch_threads)
    from avp_episode.run_config import RunConfig, run_profile, sim_values
    from avp_sim.core.factory import load_lot_param

    seeds = _seeds(args.seeds)
    overrides = {"scenario.family": args.scenario, "egos.entry_interval": args.entry_interval}
    if args.lot:
        overrides["lot_file"] = str(Path(args.lot).resolve())
    cfg = RunConfig(t_final=args.t_final, sim_overrides=overrides)
    sim = sim_values(cfg)
    lot = load_lot_param(sim["lot_file"])
    profile = run_profile(args.method, cfg)
    report = {"lot": lot.name, "scenario": args.scenario, "method": args.method, "seeds": seeds,
              "t_final": args.t_final, "entry_interval": args.entry_interval, "ego_workers": args.ego_workers,
              "cpus": os.cpu_count(), "torch_threads": _torch_threads(),
              "machine": platform.processor() or platform.machine(), "python": sys.version.split()[0], "runs": {}}
    for k in [int(x) for x in args.egos.split(",")]:
        all_t: list[float] = []
        outcomes = []
        t0 = time.perf_counter()
        for seed in seeds:
            outcome, times = run_episode(lot, sim, profile, seed, k, args.ego_workers)
            outcomes.append(outcome)
            all_t += times
            print(f"K={k} seed {seed}: {outcome}; step median {1e3 * np.median(times):.1f} ms, p95 "
                  f"{1e3 * np.percentile(times, 95):.1f} ms", flush=True)
        t = np.asarray(all_t) * 1e3
        row = {"steps": len(t), "median_ms": round(float(np.median(t)), 1), "p95_ms": round(float(np.percentile(t, 95)),
               1), "max_ms": round(float(t.max()), 1), "wall_s": round(time.perf_counter() - t0, 1),
               "load_end": [round(x, 2) for x in os.getloadavg()], "outcomes": outcomes}
        report["runs"][str(k)] = row
        print(f"K={k}: {row['steps']} lot steps, median {row['median_ms']} ms, p95 {row['p95_ms']} ms, max "
              f"{row['max_ms']} ms (load {row['load_end']})", flush=True)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""Cost of one Table I episode per method, and the full sweep extrapolated (the target: <= 2 h on 2 cores).

Runs ``--scenarios`` seeds x both modes per method in this process (one torch thread), exactly as
``avp experiment --transport inproc`` runs them (:class:`~avp_episode.ego.MethodEgo`, wall-clock caps
lifted), and times each step split into the simulator (observe + step), the method's perception (belief
update, intent CNN, prediction, Nawaz / ego intent) and the planner. The sweep estimate is
500 scenarios x 2 modes x (runnable methods) x mean CPU time per episode / ``--workers`` (CPU time: on a
shared machine the wall time also counts the other jobs).

``--profile`` adds a cProfile of all episodes (top functions by cumulative and by own time).

Usage: python bench/bench_experiment.py [--scenarios 6] [--methods all] [--workers 2] [--profile]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import os
import platform
import pstats
import time

import numpy as np
import torch

from avp_episode.ego import MethodEgo
from avp_experiment.runner import RunConfig, resolve_methods, sim_values, valid_seeds
from avp_sim.core.factory import make_world
from avp_world.lot import load_bundled_lot


def episode(lot, sim_p, profile, seed, reactive):
    world = make_world(lot, sim_p, seed, reactive)
    ego = MethodEgo(lot, profile)
    t_sim = t_perc = t_plan = 0.0
    c0 = time.process_time()
    t0 = time.perf_counter()
    while not world.done:
        a = time.perf_counter()
        obs = world.observe()
        b = time.perf_counter()
        out = ego.step(obs)
        c = time.perf_counter()
        world.step(*out.command)
        d = time.perf_counter()
        t_sim += (b - a) + (d - c)
        t_perc += out.timings["perception_time"]
        t_plan += (c - b) - out.timings["perception_time"]
    return {"wall": time.perf_counter() - t0, "cpu": time.process_time() - c0, "steps": world.metrics.steps,
            "sim": t_sim, "perception": t_perc, "planner": t_plan, "status": world.status}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenarios", type=int, default=6)
    ap.add_argument("--seed-base", type=int, default=0)
    ap.add_argument("--methods", default="all")
    ap.add_argument("--workers", type=int, default=2, help="for the sweep estimate")
    ap.add_argument("--sweep-scenarios", type=int, default=500)
    ap.add_argument("--profile", action="store_true")
    args = ap.parse_args()
    torch.set_num_threads(1)
    lot = load_bundled_lot()
    sim_p = sim_values(RunConfig())
    profiles, skipped = resolve_methods(args.methods)
    seeds, _ = valid_seeds(args.scenarios, args.seed_base, sim_p)
    prof = cProfile.Profile() if args.profile else None
    rows = []
    for p in profiles:
        eps = []
        for s in seeds:
            for reactive in (False, True):
                if prof:
                    prof.enable()
                eps.append(episode(lot, sim_p, p, s, reactive))
                if prof:
                    prof.disable()
        w = np.array([e["wall"] for e in eps])
        cpu = np.array([e["cpu"] for e in eps])
        steps = sum(e["steps"] for e in eps)
        tot = {k: sum(e[k] for e in eps) for k in ("sim", "perception", "planner", "wall")}
        rows.append((p.name, len(eps), cpu.mean(), w.mean(), np.median(w), w.max(), steps / len(eps),
                     1e3 * tot["wall"] / steps, *(100 * tot[k] / tot["wall"] for k in ("sim", "perception", "planner")),
                     sum(e["status"] == "success" for e in eps)))
    print(f"# {platform.node()} {platform.machine()}, {os.cpu_count()} CPUs, torch threads 1, "
          f"load average {os.getloadavg()[0]:.2f}; seeds {seeds[0]}..{seeds[-1]} x both modes")
    print("| method | episodes | CPU s/episode | wall s/episode | median | max | steps/episode | wall ms/step "
          "| sim % | perception % | planner % | successes |")
    print("|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]:.2f} | {r[3]:.2f} | {r[4]:.2f} | {r[5]:.2f} | {r[6]:.0f} | {r[7]:.1f} "
              f"| {r[8]:.0f} | {r[9]:.0f} | {r[10]:.0f} | {r[11]}/{r[1]} |")
    per_method = sum(r[2] for r in rows)  # CPU seconds: the estimate assumes the workers get whole cores
    n = 2 * args.sweep_scenarios
    print(f"\nfull sweep estimate: {args.sweep_scenarios} scenarios x 2 modes x {len(rows)} methods = "
          f"{n * len(rows)} episodes, {n * per_method:.0f} CPU-s = {n * per_method / args.workers / 3600:.2f} h "
          f"on {args.workers} workers" + (f" (not runnable: {sorted(skipped)})" if skipped else ""))
    if prof:
        for key in ("cumulative", "tottime"):
            s = io.StringIO()
            pstats.Stats(prof, stream=s).sort_stats(key).print_stats(25)
            print(f"\n## cProfile by {key}\n" + "\n".join(s.getvalue().splitlines()[:60]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

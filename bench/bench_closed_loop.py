#!/usr/bin/env python3
"""In-process closed-loop step time on any lot and scenario family (the target: the busy DLP-scale lot at 10 Hz).

Each episode runs the simulator core and the method's in-process ego chain (:class:`MethodEgo`: the belief node's
core with the intent CNN, the prediction, the planner) on one thread, with the planner's wall-clock caps as in the
live graph (not lifted). Per step it times: **sense** (the simulator's occlusion-aware observation, §III-A; with
``--sim-param sensing.model=realistic`` the noisy detections of avp_sensing.noisy), **track** (the tracker,
avp_tracking; 0 with exact sensing),
**belief** (eq. 7-8 with the BEVs and the intent CNN), **predict** (§V-C), **plan** (§V-D) and the **loop**
(sense + belief + predict + plan + the simulator's step). Building the scenario is not timed. Printed: median and
p95 of each over all steps, per episode and in all, with the episodes' outcomes and the machine's load.

Usage:
    python bench/bench_closed_loop.py --lot src/avp_world/avp_world/maps/dlp_lot.yaml --scenario busy \\
        [--method bezier] [--seeds 0-4] [--t-final 60] [--json out/bench_closed_loop.json] \\
        [--planner-param KEY=VALUE ...]
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


def _seeds(spec: str) -> list[int]:
    out: list[int] = []
    for part in spec.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b) + 1)) if b else [int(a)]
    return out


def run_episode(lot, sim: dict, profile, seed: int, reactive: bool) -> tuple[dict, dict[str, list[float]]]:
    from avp_episode.ego import MethodEgo
    from avp_episode.sensing import sensed_observer
    from avp_sim.core.factory import make_world

    world = make_world(lot, sim, seed, reactive)
    noisy = sensed_observer(world, sim, seed)  # sensing.model other than exact: the sensing model and the tracker
    ego = MethodEgo(lot, profile, deterministic=False)
    t: dict[str, list[float]] = {k: [] for k in ("sense", "track", "belief", "predict", "plan", "loop")}
    while not world.done:
        t0 = time.perf_counter()
        if noisy is None:
            obs = world.observe()
            ts = time.perf_counter()
        else:
            frame = noisy.sensor.sense(world)
            ts = time.perf_counter()
            obs = noisy.perception.observe(frame)
        t1 = time.perf_counter()
        out = ego.step(obs)
        world.step(*out.command)
        t2 = time.perf_counter()
        t["sense"].append(ts - t0)
        t["track"].append(t1 - ts)
        t["belief"].append(out.timings["belief_time"])
        t["predict"].append(out.timings["prediction_time"])
        t["plan"].append(out.timings["planner_time"])
        t["loop"].append(t2 - t0)
    m = world.metrics
    outcome = {"seed": seed, "reactive": reactive, "status": world.status, "collision_with": m.collision_with,
               "collision_at_fault": m.collision_at_fault, "parked_spot_id": m.parked_spot_id, "steps": m.steps,
               "moving_vehicles": int(world.is_dynamic.sum()), "pedestrians": len(world.ped_pos)}
    return outcome, t


def _stats(v: list[float]) -> dict[str, float]:
    a = np.asarray(v) * 1e3
    return {"median_ms": round(float(np.median(a)), 1), "p95_ms": round(float(np.percentile(a, 95)), 1),
            "max_ms": round(float(a.max()), 1)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lot", default="", help="lot map YAML (default: the bundled paper lot)")
    ap.add_argument("--scenario", default="busy", choices=("paper", "busy"))
    ap.add_argument("--method", default="bezier")
    ap.add_argument("--seeds", default="0-4", help="e.g. 0-4 or 1,3,7")
    ap.add_argument("--modes", default="reactive", choices=("reactive", "non-reactive", "both"))
    ap.add_argument("--t-final", type=float, default=60.0)
    ap.add_argument("--json", default="", help="also write the figures here")
    ap.add_argument("--planner-param", action="append", metavar="KEY=VALUE",
                    help="an avp_planner parameter for the method (as `avp experiment --planner-param`)")
    ap.add_argument("--sim-param", action="append", default=[], metavar="KEY=VALUE",
                    help="an avp_sim parameter (as `avp experiment --sim-param`), e.g. agents_yield=true")
    args = ap.parse_args()

    import torch

    from avp_episode.run_config import RunConfig, run_profile, sim_values
    from avp_experiment.runner import parse_planner_params, parse_sim_params
    from avp_sim.core.factory import load_lot_param

    torch.set_num_threads(1)
    over = {**parse_sim_params(args.sim_param), "scenario.family": args.scenario}
    if args.lot:
        over["lot_file"] = str(Path(args.lot).resolve())
    cfg = RunConfig(t_final=args.t_final, sim_overrides=over,
                    planner_overrides=parse_planner_params(args.planner_param))
    sim = sim_values(cfg)
    lot = load_lot_param(sim["lot_file"])
    profile = run_profile(args.method, cfg)
    modes = {"reactive": (True,), "non-reactive": (False,), "both": (True, False)}[args.modes]
    load0 = os.getloadavg()
    print(f"# {lot.name} ({lot.n_spots} spots), scenario {args.scenario}, method {args.method} "
          f"{cfg.planner_overrides or ''} {args.sim_param or ''}, t_f {args.t_final} s; "
          f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, 1 torch thread, load average "
          f"{load0[0]:.2f} before")
    print("| seed | mode | outcome | steps | moving cars | pedestrians | loop median / p95 ms | sense | track | "
          "belief | predict | plan |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    every: dict[str, list[float]] = {}
    episodes = []
    for seed in _seeds(args.seeds):
        for reactive in modes:
            outcome, t = run_episode(lot, sim, profile, seed, reactive)
            episodes.append({**outcome, "times": {k: _stats(v) for k, v in t.items()}})
            for k, v in t.items():
                every.setdefault(k, []).extend(v)
            s = episodes[-1]["times"]
            what = outcome["status"] + (f" ({outcome['collision_with']}, "
                                        f"{'at fault' if outcome['collision_at_fault'] else 'not at fault'})"
                                        if outcome["status"] == "collision" else "")
            print(f"| {seed} | {'reactive' if reactive else 'non-reactive'} | {what} | {outcome['steps']} | "
                  f"{outcome['moving_vehicles']} | {outcome['pedestrians']} | "
                  + " | ".join(f"{s[k]['median_ms']} / {s[k]['p95_ms']}" for k in
                               ("loop", "sense", "track", "belief", "predict", "plan")) + " |", flush=True)
    total = {k: _stats(v) for k, v in every.items()}
    load1 = os.getloadavg()
    print(f"# all {len(every['loop'])} steps: " + ", ".join(f"{k} median {v['median_ms']} ms, p95 {v['p95_ms']} ms"
                                                        for k, v in total.items()))
    print(f"# load average {load1[0]:.2f} after; target loop median <= 50 ms: "
          f"{'met' if total['loop']['median_ms'] <= 50 else 'NOT met'}, p95 <= 100 ms: "
          f"{'met' if total['loop']['p95_ms'] <= 100 else 'NOT met'}")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({"args": vars(args), "all": total, "episodes": episodes}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

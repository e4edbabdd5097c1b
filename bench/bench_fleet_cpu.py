#!/usr/bin/env python3
"""CPU seconds of fleet episodes as the fleet grid runs them, and a digest of their records.

Runs each seed's episode in this process exactly as ``avp experiment --suite fleet`` runs a cell
(:func:`avp_episode.fleet.run_fleet_inproc`, lock-step, one torch thread, no wall-clock caps) and prints the
process CPU time of each episode and a SHA-256 of its records less their ``timings``. To compare two builds, run
the script in both (the reference in a git worktree, its ``src/*`` first on ``PYTHONPATH``) on the same machine in
the same sitting: equal digests mean equal episodes, and the CPU ratio is the speed-up (docs/benchmarks.md).

Usage: python bench/bench_fleet_cpu.py [--lot FILE] [--scenario busy] [--egos 4] [--method bezier]
       [--planner-param collision.reactive_steps=2 ...] [--seeds 0-2] [--t-final 70] [--json OUT]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import platform
import subprocess
import time
from pathlib import Path

import torch
from bench_closed_loop import _seeds  # noqa: E402  (bench/ is the script's directory: one seed-range parser)

from avp_episode.fleet import run_fleet_inproc
from avp_episode.run_config import RunConfig, run_profile, sim_values
from avp_experiment.runner import parse_planner_params
from avp_world.lot import load_bundled_lot, load_lot

ROW_BEZIER = ["collision.reactive_steps=2", "collision.reactive_evidence=assumed"]  # the fleet suite's `bezier` row


def digest(records: list[dict]) -> str:
    """SHA-256 of the records as the runner writes them (JSON), less the wall-clock ``timings``."""
    rows = [json.dumps({k: v for k, v in r.items() if k != "timings"}, sort_keys=True) for r in records]
    return hashlib.sha256("\n".join(rows).encode()).hexdigest()[:16]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lot", default="src/avp_world/avp_world/maps/dlp_lot.yaml")
    ap.add_argument("--scenario", default="busy", choices=("paper", "busy"))
    ap.add_argument("--egos", type=int, default=4)
    ap.add_argument("--method", default="bezier")
    ap.add_argument("--planner-param", action="append", default=None, metavar="KEY=VALUE",
                    help="planner overrides (default: the fleet suite's bezier row)")
    ap.add_argument("--seeds", default="0-2", help="a-b or comma-separated")
    ap.add_argument("--t-final", type=float, default=70.0)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    torch.set_num_threads(1)
    planner = parse_planner_params(ROW_BEZIER if args.planner_param is None else args.planner_param)
    sim = {"scenario.family": args.scenario}
    if args.lot:
        sim["lot_file"] = args.lot
    cfg = RunConfig(t_final=args.t_final, sim_overrides=sim, planner_overrides=planner)
    lot = load_lot(args.lot) if args.lot else load_bundled_lot()
    profiles = [run_profile(args.method, cfg) for _ in range(args.egos)]
    rows = []
    for seed in _seeds(args.seeds):
        c0, t0 = time.process_time(), time.perf_counter()
        records = run_fleet_inproc(lot, sim_values(cfg), profiles, seed, True, cfg)
        cpu, wall = time.process_time() - c0, time.perf_counter() - t0
        parked = sum(r["status"] == "success" for r in records)
        rows.append({"seed": seed, "cpu_s": round(cpu, 2), "wall_s": round(wall, 2), "parked": parked,
                     "digest": digest(json.loads(json.dumps(records)))})
        print(f"seed {seed}: {cpu:7.1f} CPU-s ({wall:6.1f} s wall), {parked} of {args.egos} parked, "
              f"records {rows[-1]['digest']}", flush=True)
    total = sum(r["cpu_s"] for r in rows)
    print(f"total {total:.1f} CPU-s over {len(rows)} episodes")
    if args.json:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
        args.json.write_text(json.dumps({"commit": commit, "machine": platform.processor() or platform.machine(),
                                         "argv": vars(args) | {"json": str(args.json)}, "episodes": rows,
                                         "total_cpu_s": total}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

#!/usr/bin/env python3
"""Scaling of ``avp experiment`` on Ray vs the local backend.

The same sweep (``--methods``, ``--scenarios`` seeds, ``--mode``) is run four ways, each into a fresh folder:
the local backend with 1 and 2 worker processes, and ``--backend ray`` on a Ray cluster of separate
``ray start`` processes on loopback (:class:`LocalRayCluster`) with 1 worker process (a 1-CPU head) and with 2
(a 1-CPU head and a 1-CPU worker node). Each run's wall time is the invocation's own (``runs.jsonl``: from the
first episode submitted to the last recorded, Ray's connection included; the cluster's start is not). Printed per
run: episodes per second, and the per-episode overhead — (wall x workers - sum of the episodes' own wall times) /
episodes, the time a worker spent on anything but an episode — beside the median episode time. Ray's overhead is
the difference to the local backend's at the same worker count. The records of all four runs are checked equal
(timing fields aside).

Ray workers run at nice 15 (Ray's default): measure on an otherwise idle machine.

Usage:
    python bench/bench_ray.py [--methods bezier] [--scenarios 20] [--mode both] [--out out/bench_ray]
        [--json out/bench_ray.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path


def run(out: Path, args: argparse.Namespace, *extra: str, env: dict | None = None) -> dict:
    """One ``avp experiment`` invocation; its wall time, the episodes' own wall times and its records."""
    from avp_episode.metrics import comparable
    from avp_experiment.runner import RESULTS_FILE, read_results, record_key

    shutil.rmtree(out, ignore_errors=True)
    cmd = [sys.executable, "-m", "avp_bringup.cli", "experiment", "--methods", args.methods, "--scenarios",
           str(args.scenarios), "--mode", args.mode, "--no-progress", "--out", str(out), *extra]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, env=env)
    wall = json.loads((out / "runs.jsonl").read_text().splitlines()[-1])["wall_s"]
    raw = read_results(out / RESULTS_FILE)
    return {"wall_s": wall, "episode_wall_s": [r["timings"]["wall_s"] for r in raw],
            "records": {record_key(r): comparable(r) for r in raw}}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--methods", default="bezier")
    p.add_argument("--scenarios", type=int, default=20)
    p.add_argument("--mode", default="both")
    p.add_argument("--out", default="out/bench_ray")
    p.add_argument("--json", default="")
    args = p.parse_args()
    from avp_experiment.ray_backend import LocalRayCluster
    from avp_experiment.results import code_commit

    out = Path(args.out)
    runs: dict[str, dict] = {}
    for n in (1, 2):
        runs[f"local, {n} worker(s)"] = {"workers": n, **run(out / f"local{n}", args, "--workers", str(n))}
        tmp = tempfile.mkdtemp(prefix="avpray", dir="/tmp")
        with LocalRayCluster(tmp, cpus=(1,) * n) as cluster:
            runs[f"ray, {n} worker(s)"] = {"workers": n, **run(out / f"ray{n}", args, "--backend", "ray",
                                                                "--address", cluster.address, env=cluster.env)}
        shutil.rmtree(tmp, ignore_errors=True)
    first = next(iter(runs.values()))["records"]
    equal = all(r["records"] == first for r in runs.values())
    print(f"commit {code_commit()}, {platform.node()}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f}; "
          f"{len(first)} episodes ({args.methods}, {args.scenarios} scenarios, mode {args.mode}); "
          f"records equal across the four runs: {equal}")
    print("| run | wall s | episodes/s | median episode s | overhead per episode s | overhead / median episode |")
    print("|---|---|---|---|---|---|")
    table = {}
    for name, r in runs.items():
        n_ep = len(r["records"])
        med = statistics.median(r["episode_wall_s"])
        over = (r["wall_s"] * r["workers"] - sum(r["episode_wall_s"])) / n_ep
        table[name] = {"wall_s": r["wall_s"], "episodes_per_s": n_ep / r["wall_s"], "median_episode_s": med,
                       "overhead_per_episode_s": over}
        print(f"| {name} | {r['wall_s']:.1f} | {n_ep / r['wall_s']:.2f} | {med:.3f} | {over:.3f} | "
              f"{100 * over / med:.1f} % |")
    for n in (1, 2):
        loc, ray = table[f"local, {n} worker(s)"], table[f"ray, {n} worker(s)"]
        extra = ray["overhead_per_episode_s"] - loc["overhead_per_episode_s"]
        print(f"Ray's overhead beyond the local backend's, {n} worker(s): {extra * 1000:.0f} ms per episode = "
              f"{100 * extra / loc['median_episode_s']:.1f} % of the median episode")
    if args.json:
        Path(args.json).write_text(json.dumps({"equal": equal, "runs": table}, indent=1))
    return 0 if equal else 1


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""Seed finding (avp_experiment/seeds.py): the wall time of finding ``--seeds`` seeds that build a scenario, one after
another and on ``--workers`` processes, with no seed cache. Both must give the same seeds; printed: the two times and
their ratio, with the machine's load.

Usage:
    python bench/bench_seeds.py [--lot src/avp_world/avp_world/maps/dlp_lot.yaml --scenario busy] [--seeds 12]
        [--seed-base 0] [--workers 2]
"""

from __future__ import annotations

import argparse
import os
import time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lot", default="", help="lot map YAML (default: the paper's lot)")
    ap.add_argument("--scenario", default="paper", choices=("paper", "busy"), help="scenario.family")
    ap.add_argument("--seeds", type=int, default=12)
    ap.add_argument("--seed-base", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--t-final", type=float, default=60.0)
    args = ap.parse_args()

    from avp_episode.run_config import RunConfig, sim_values
    from avp_experiment import runner
    from avp_experiment.seeds import seed_builds, valid_seeds

    sim = runner._with_lot(runner.parse_sim_params([f"scenario.family={args.scenario}"]), args.lot or None)
    p = sim_values(RunConfig(t_final=args.t_final, sim_overrides=sim))
    seed_builds(p, args.seed_base)  # the first generation's one-off costs (imports, the lot's lane graph), not timed
    print(f"load before: {[round(x, 2) for x in os.getloadavg()]}")
    t0 = time.perf_counter()
    serial = valid_seeds(args.seeds, args.seed_base, p)
    t_serial = time.perf_counter() - t0
    t0 = time.perf_counter()
    pooled = valid_seeds(args.seeds, args.seed_base, p, workers=args.workers)
    t_pool = time.perf_counter() - t0
    assert pooled == serial, (pooled, serial)
    print(f"{args.scenario} lot, {args.seeds} seeds from {args.seed_base} (skipped {serial[1]}): one after another "
          f"{t_serial:.1f} s, on {args.workers} workers {t_pool:.1f} s (pool start included): "
          f"{t_serial / t_pool:.2f}x; load after: {[round(x, 2) for x in os.getloadavg()]}")


if __name__ == "__main__":
    main()

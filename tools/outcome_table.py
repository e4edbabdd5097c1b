"""Outcomes of an experiment folder per method, with who collided with what and whether the ego was at fault.

    python tools/outcome_table.py OUT [--mode reactive]

Prints a Markdown table: episodes, success with its 95 % Wilson interval, timeouts, collisions with vehicles and
with pedestrians (at fault: the ego was moving, docs/metrics.md) and with the boundary, spots stolen, and the
median parking time of the successes. Duplicate (method, seed, mode) records count once (the first).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

from avp_episode.metrics import wilson
from avp_experiment.results import open_records


def _collisions(rs: list[dict], prefix: str) -> str:
    c = [r for r in rs if r["collision"] and r["collision_with"].startswith(prefix)]
    return f"{len(c)} ({sum(bool(r.get('collision_at_fault')) for r in c)})"


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--mode", default="", help="only this mode (reactive | non_reactive)")
    args = ap.parse_args(argv)
    seen: dict[tuple, dict] = {}
    with open_records(Path(args.out)) as lines:  # OUT's episodes.jsonl or episodes.jsonl.gz
        for line in lines:
            if line.strip():
                r = json.loads(line)
                if not args.mode or r["mode"] == args.mode:
                    seen.setdefault((r["method"], r["seed"], r["mode"]), r)
    by: dict[str, list[dict]] = {}
    for r in seen.values():
        by.setdefault(r["method"], []).append(r)
    common = set.intersection(*({r["seed"] for r in rs} for rs in by.values())) if by else set()
    print(f"{len(common)} seeds run by every method ({min(common, default='-')}..{max(common, default='-')}); "
          "only those are counted")
    print("| method | episodes | success [95 % CI] | timeout | vehicle collisions (at fault) | pedestrian collisions "
          "(at fault) | boundary | stolen | median parking time s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for m, rs in by.items():
        rs = [r for r in rs if r["seed"] in common]
        n = len(rs)
        k = sum(r["success"] for r in rs)
        lo, hi = wilson(k, n)


        pt = [r["parking_time"] for r in rs if r["success"] and r["parking_time"] is not None]
        print(f"| {m} | {n} | {100 * k / n:.1f} % [{100 * lo:.1f}, {100 * hi:.1f}] | "
              f"{sum(r['status'] == 'timeout' for r in rs)} | {_collisions(rs, 'vehicle')} | "
              f"{_collisions(rs, 'pedestrian')} | "
              f"{sum(r['collision_with'] == 'boundary' for r in rs)} | {sum(r['spot_stolen'] for r in rs)} | "
              f"{statistics.median(pt) if pt else float('nan'):.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

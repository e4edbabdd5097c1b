#!/usr/bin/env python3
"""Before/after table of the ego's motion over the same episodes: success, parking time, direction
reversals and U-turns per episode, per mode, from two experiment folders with the same method and seeds.

    python tools/motion_table.py BEFORE AFTER [--method bezier]

Prints Markdown: success % with 95 % Wilson intervals and the exact McNemar p on the paired outcomes; mean
parking time of the successful episodes (± std) and over the episodes both parked (paired mean difference);
reversals and U-turns per episode (mean, and how many episodes have any).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from avp_episode.metrics import wilson
from avp_experiment.results import open_records


def _records(folder: str, method: str) -> dict:
    out = {}
    with open_records(Path(folder)) as lines:  # its episodes.jsonl or episodes.jsonl.gz
        for line in lines:
            if line.strip():
                r = json.loads(line)
                if r["method"] == method:
                    out[(r["seed"], r["mode"])] = r
    return out


def mcnemar(b: int, c: int) -> float:
    """Exact two-sided McNemar p of b vs c discordant pairs."""
    n = b + c
    if n == 0:
        return 1.0
    k = min(b, c)
    return min(1.0, 2 * sum(math.comb(n, i) for i in range(k + 1)) / 2 ** n)


def _mean_std(xs: list[float]) -> str:
    if not xs:
        return "—"
    m = sum(xs) / len(xs)
    s = math.sqrt(sum((x - m) ** 2 for x in xs) / max(1, len(xs) - 1))
    return f"{m:.2f} ± {s:.2f}"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("before")
    p.add_argument("after")
    p.add_argument("--method", default="bezier")
    a = p.parse_args(argv)
    before, after = _records(a.before, a.method), _records(a.after, a.method)
    keys = sorted(set(before) & set(after))
    print(f"{a.method}: {len(keys)} episodes in both folders\n")
    print("| mode | run | n | success % [95 %] | parking time s (successes) | reversals / episode | episodes with a "
          "reversal | U-turns / episode | episodes with a U-turn |")
    print("|---|---|--:|--:|--:|--:|--:|--:|--:|")
    for mode in sorted({k[1] for k in keys}):
        ks = [k for k in keys if k[1] == mode]
        for name, recs in (("before", before), ("after", after)):
            rs = [recs[k] for k in ks]
            n, s = len(rs), sum(r["success"] for r in rs)
            lo, hi = wilson(s, n)
            pt = [r["parking_time"] for r in rs if r["success"] and r["parking_time"] is not None]
            rev = [r.get("reversals", 0) for r in rs]
            ut = [r.get("u_turns", 0) for r in rs]
            print(f"| {mode} | {name} | {n} | {100 * s / n:.1f} [{100 * lo:.1f}, {100 * hi:.1f}] | {_mean_std(pt)} | "
                  f"{sum(rev) / n:.2f} | {sum(x > 0 for x in rev)} | {sum(ut) / n:.3f} | {sum(x > 0 for x in ut)} |")
        b = sum(before[k]["success"] and not after[k]["success"] for k in ks)
        c = sum(after[k]["success"] and not before[k]["success"] for k in ks)
        both = [k for k in ks if before[k]["success"] and after[k]["success"]]
        diff = [after[k]["parking_time"] - before[k]["parking_time"] for k in both]
        changed = sum(before[k]["parking_time"] != after[k]["parking_time"] or before[k]["status"] != after[k]["status"]
                      for k in ks)
        print(f"| {mode} | paired | | only before succeeded {b}, only after {c}: McNemar p = {mcnemar(b, c):.3g} | "
              f"after − before, both parked ({len(both)}): {_mean_std(diff)} | episodes whose outcome or time "
              f"changed: {changed} | | | |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""`contested` non-reactive per method, the shipped default against `wary` on the same seeds (docs/results/contested).

    python tools/contested_table.py [--mode non_reactive]

Reads the committed records: the shipped default's (contested/default_all_methods, contested/default_oracle,
contested/bezier_default) and `wary`'s (contested/wary_all_methods). Prints Markdown: per method the episodes, failed
or stolen (not parked, or parked in a spot another car was heading for) with its 95 % Wilson interval, collisions (at
fault), timeouts, stolen, `wary`'s count on the same seeds, and the discordant seeds with the exact McNemar p.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from motion_table import mcnemar

from avp_episode.metrics import wilson
from avp_experiment.results import read_results, records_file

RESULTS = Path(__file__).resolve().parents[1] / "docs/results/contested"
DEFAULT = ("default_all_methods", "default_oracle", "bezier_default")
METHODS = ("bezier", "constant_velocity", "hybrid_astar", "learned", "implicit", "nawaz", "oracle", "blind")


def _load(folders, mode: str) -> dict[tuple[str, int], dict]:
    out: dict[tuple[str, int], dict] = {}
    for f in folders:
        for r in read_results(records_file(RESULTS / f)):
            if r["mode"] == mode:
                out.setdefault((r["method"], r["seed"]), r)
    return out


def _bad(r: dict) -> bool:
    return (not r["success"]) or bool(r["spot_stolen"])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mode", default="non_reactive")
    args = ap.parse_args(argv)
    new, wary = _load(DEFAULT, args.mode), _load(["wary_all_methods"], args.mode)
    print("| method | episodes | failed or stolen [95 % CI] | collisions (at fault) | timeouts | stolen | "
          "`wary` on the same seeds | only default / only `wary`, p |\n|---|--:|---|---|--:|--:|---|---|")
    for m in METHODS:
        rs = {s: r for (mm, s), r in new.items() if mm == m}
        ws = {s: r for (mm, s), r in wary.items() if mm == m}
        if not rs:
            continue
        n, k = len(rs), sum(_bad(r) for r in rs.values())
        lo, hi = wilson(k, n)
        col = [r for r in rs.values() if r["collision"]]
        common = sorted(set(rs) & set(ws))
        b = sum(_bad(rs[s]) and not _bad(ws[s]) for s in common)
        c = sum(_bad(ws[s]) and not _bad(rs[s]) for s in common)
        kw = sum(_bad(ws[s]) for s in common)
        fault = sum(bool(r.get("collision_at_fault")) for r in col)
        timeouts = sum(r["status"] == "timeout" for r in rs.values())
        stolen = sum(bool(r["spot_stolen"]) for r in rs.values())
        print(f"| {m} | {n} | {k} = {100 * k / n:.1f} % [{100 * lo:.1f}, {100 * hi:.1f}] | {len(col)} ({fault}) | "
              f"{timeouts} | {stolen} | {kw} of {len(common)} = {100 * kw / max(len(common), 1):.1f} % | {b} / {c}, "
              f"p = {mcnemar(b, c):.2g} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

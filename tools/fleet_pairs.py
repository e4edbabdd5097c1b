"""Paired comparisons of fleets on the same seeds (docs/results/fleet/): per episode, whether any ego lost a spot to
another ego, whether every ego parked, and the egos' parking times; exact McNemar p for the first two against a
reference fleet.

    python tools/fleet_pairs.py OUT [OUT ...] [--ref blind]      # folders of `avp experiment --egos K` runs
    python tools/fleet_pairs.py --by-folder docs/results/fleet/grid/paper_k2/*     # a column of the fleet suite

Prints a Markdown table: fleet, episodes, episodes with an ego-ego spot loss (95 % Wilson interval), episodes where
every ego parked, both against the reference on the seeds they share (discordant pairs and p).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from motion_table import mcnemar  # noqa: E402  (tools/ is the script's directory)

from avp_episode.fleet import FLEET_PREFIX
from avp_episode.metrics import wilson
from avp_experiment.results import open_records


def episodes(folders: list[Path], planner_tag: dict[Path, str],
             by_folder: bool = False) -> dict[str, dict[int, list[dict]]]:
    """fleet name (its first ego's method, or with ``by_folder`` the folder's name) -> seed -> the episode's records
    (one per ego)."""
    out: dict[str, dict[int, list[dict]]] = {}
    for f in folders:
        if f.is_file() and not f.name.endswith((".jsonl", ".jsonl.gz")):
            continue  # a glob of a suite column also matches its seed cache (OUT/<column>/seeds.json)
        with open_records(f) as lines:  # its episodes.jsonl or episodes.jsonl.gz
            for line in lines:
                if line.strip():
                    r = json.loads(line)
                    name = f.name if by_folder else r["method"][len(FLEET_PREFIX):].split(",")[0]
                    name += planner_tag.get(f, "")
                    out.setdefault(name, {}).setdefault(r["seed"], []).append(r)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("folders", nargs="+", type=Path)
    ap.add_argument("--ref", default="blind")
    ap.add_argument("--tag", action="append", default=[], metavar="FOLDER=SUFFIX",
                    help="name the fleets of FOLDER with SUFFIX (e.g. a planner profile)")
    ap.add_argument("--by-folder", action="store_true",
                    help="name each fleet by its folder (a suite's row folders: bezier, wary, reserve, ...)")
    args = ap.parse_args(argv)
    tags = {Path(k): v for k, _, v in (t.partition("=") for t in args.tag)}
    eps = episodes(args.folders, tags, args.by_folder)
    ref = eps.get(args.ref, {})
    vs = f"vs {args.ref} (b / c, p)"
    rows = [f"| fleet | episodes | with an ego-ego spot loss [95 % CI] | {vs} | every ego parked | {vs} |",
            "|---|--:|---|---|---|---|"]
    for name, by_seed in sorted(eps.items()):
        n = len(by_seed)
        lost = {s: any(r["spots_lost_to_ego"] for r in rs) for s, rs in by_seed.items()}
        parked = {s: all(r["success"] for r in rs) for s, rs in by_seed.items()}
        k = sum(lost.values())
        lo, hi = wilson(k, n)
        cells = []
        for mine, theirs in ((lost, {s: any(r["spots_lost_to_ego"] for r in rs) for s, rs in ref.items()}),
                             (parked, {s: all(r["success"] for r in rs) for s, rs in ref.items()})):
            common = sorted(set(mine) & set(theirs))
            if name == args.ref or not common:
                cells.append("—")
                continue
            b = sum(mine[s] and not theirs[s] for s in common)
            c = sum(theirs[s] and not mine[s] for s in common)
            cells.append(f"{b} / {c}, p = {mcnemar(b, c):.3g} ({len(common)} seeds)")
        rows.append(f"| {name} | {n} | {k} = {100 * k / n:.1f} % [{100 * lo:.1f}, {100 * hi:.1f}] | {cells[0]} | "
                    f"{sum(parked.values())} of {n} | {cells[1]} |")
    print("\n".join(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())

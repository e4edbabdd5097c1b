"""Arms of an ablation side by side, paired against a reference arm (docs/research/unfreezing.md).

    python tools/arm_table.py NAME=EPISODES.jsonl[:METHOD] [NAME=...] [--ref NAME] [--mode reactive]

Each arm is an episodes file (an `avp experiment` folder's episodes.jsonl or episodes.jsonl.gz, or any file of
records, plain or gzip-compressed), optionally restricted to one method. Prints Markdown: per arm the seeds, success
with its 95 % Wilson interval, timeouts, collisions (at fault: the ego moved in the step it collided,
docs/metrics.md), spots stolen and the mean interrupted timesteps; then each arm against ``--ref`` (default: the
first) on the seeds both have: the successes of each and the exact McNemar p of the discordant pairs. A (method,
seed, mode) recorded twice counts once.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from motion_table import mcnemar

from avp_episode.metrics import wilson
from avp_experiment.results import open_records


def load(spec: str, mode: str) -> tuple[str, dict[int, dict]]:
    name, _, rest = spec.partition("=")
    path, _, method = rest.partition(":")
    out: dict[int, dict] = {}
    with open_records(Path(path)) as lines:  # a .jsonl or .jsonl.gz file, or a run folder's records
        for line in lines:
            if not line.strip():
                continue
            r = json.loads(line)
            if (method and r["method"] != method) or (mode and r["mode"] != mode):
                continue
            out.setdefault(int(r["seed"]), r)
    return name, out


def _seeds(seeds: list[int]) -> str:
    runs, start = [], seeds[0]
    for a, b in zip(seeds, seeds[1:] + [None], strict=True):
        if b != a + 1:
            runs.append(f"{start}–{a}" if a != start else f"{a}")
            start = b
    return ", ".join(runs)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("arms", nargs="+")
    ap.add_argument("--ref", default="")
    ap.add_argument("--mode", default="reactive", help="reactive | non_reactive | '' (both)")
    args = ap.parse_args(argv)
    arms = dict(load(a, args.mode) for a in args.arms)
    print("| arm | seeds | success [95 % CI] | timeouts | collisions (at fault) | stolen | mean interrupted steps |")
    print("|---|---|---|--:|---|--:|--:|")
    for name, rs in arms.items():
        v = list(rs.values())
        n, s = len(v), sum(r["status"] == "success" for r in v)
        lo, hi = wilson(s, n)
        print(f"| {name} | {_seeds(sorted(rs))} ({n}) | {s} = {100 * s / n:.1f} % [{100 * lo:.1f}, {100 * hi:.1f}] | "
              f"{sum(r['status'] == 'timeout' for r in v)} | {sum(bool(r['collision']) for r in v)} "
              f"({sum(bool(r.get('collision_at_fault')) for r in v)}) | {sum(bool(r.get('spot_stolen')) for r in v)} | "
              f"{sum(r['interrupted_steps'] for r in v) / n:.1f} |")
    ref = args.ref or next(iter(arms))
    print(f"\n| arm vs {ref} | common seeds | success arm / {ref} | only arm | only {ref} | McNemar p |")
    print("|---|--:|---|--:|--:|--:|")
    for name, rs in arms.items():
        if name == ref:
            continue
        common = sorted(set(rs) & set(arms[ref]))
        a = [rs[k]["status"] == "success" for k in common]
        b = [arms[ref][k]["status"] == "success" for k in common]
        only_a = sum(x and not y for x, y in zip(a, b, strict=True))
        only_b = sum(y and not x for x, y in zip(a, b, strict=True))
        print(f"| {name} | {len(common)} | {sum(a)} / {sum(b)} | {only_a} | {only_b} | {mcnemar(only_a, only_b):.3g} |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

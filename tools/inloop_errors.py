"""The predictors' minADE / minFDE in the loop, per sensing preset, paired on episodes (docs/results/sensing/README.md,
"The predictors in the loop").

    python tools/inloop_errors.py exact=DIR realistic=DIR harsh=DIR [--methods hybrid_astar,...] [--seeds 0-49]
        [--extra bezier:realistic=DIR ...]

Each DIR is a folder of ``avp experiment`` records (episodes.jsonl or .jsonl.gz); ``--extra METHOD:PRESET=DIR``
reads one method's records of one preset from another folder (a sensing suite's cell). The errors are the runner's
(docs/experiment.md, ``min_ade``/``min_fde``): every step, every observed car, the best mode against the vehicle its
track follows, over 4 s; an episode's value is the mean over its samples. Per method and preset: the episodes that
have a value in every preset (same seed and mode), their samples, the mean of the episode values, and minFDE over
exact sensing's on the same episodes. The ego drives differently under noise, so the samples differ too.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from avp_experiment.results import read_results


def _seeds(text: str) -> set[int] | None:
    if not text:
        return None
    a, _, b = text.partition("-")
    return set(range(int(a), int(b or a) + 1))


def collect(sources: dict[str, list[Path]], extra: dict[tuple[str, str], Path], methods: list[str],
            seeds: set[int] | None) -> dict:
    """(method, preset) -> {(seed, mode): (min_ade, min_fde, samples)} for episodes with a value."""
    out: dict = {}

    def add(method: str, preset: str, recs: list[dict]) -> None:
        cell = out.setdefault((method, preset), {})
        for r in recs:
            if r.get("method") != method or r.get("min_ade") is None:
                continue
            if seeds is not None and int(r["seed"]) not in seeds:
                continue
            cell[(int(r["seed"]), r["mode"])] = (float(r["min_ade"]), float(r["min_fde"]), int(r["ade_samples"]))

    for preset, dirs in sources.items():
        for d in dirs:
            recs = read_results(d)
            for m in methods:
                if (m, preset) not in extra:
                    add(m, preset, recs)
    for (m, preset), d in extra.items():
        add(m, preset, read_results(d))
    return out


def table(cells: dict, presets: list[str], methods: list[str]) -> str:
    rows = ["| predictor | episodes | " + " | ".join(f"{p}: samples, minADE / minFDE (m)" for p in presets)
            + " | " + " | ".join(f"minFDE {p} / exact" for p in presets if p != "exact") + " |",
            "|---|--:|" + "--:|" * (2 * len(presets) - 1)]
    for m in methods:
        keys = set.intersection(*(set(cells.get((m, p), {})) for p in presets))
        if not keys:
            continue
        ks = sorted(keys, key=lambda k: (k[0], k[1]))
        vals = {p: np.array([cells[(m, p)][k] for k in ks]) for p in presets}
        body = [f"{int(v[:, 2].sum())}: {v[:, 0].mean():.2f} / {v[:, 1].mean():.2f}" for v in vals.values()]
        ratio = [f"{vals[p][:, 1].mean() / vals['exact'][:, 1].mean():.2f}" for p in presets if p != "exact"]
        rows.append(f"| {m} | {len(ks)} | " + " | ".join(body) + " | " + " | ".join(ratio) + " |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sources", nargs="+", metavar="PRESET=DIR", help="records of each sensing preset (exact first)")
    ap.add_argument("--methods", default="bezier,constant_velocity,hybrid_astar,learned")
    ap.add_argument("--seeds", default="", metavar="A-B", help="only these seeds")
    ap.add_argument("--extra", action="append", default=[], metavar="METHOD:PRESET=DIR")
    args = ap.parse_args(argv)
    sources: dict[str, list[Path]] = {}
    for s in args.sources:
        preset, _, d = s.partition("=")
        sources.setdefault(preset, []).append(Path(d))
    if "exact" not in sources:
        ap.error("name the exact-sensing records: exact=DIR")
    extra = {}
    for s in args.extra:
        key, _, d = s.partition("=")
        method, _, preset = key.partition(":")
        extra[(method, preset)] = Path(d)
    methods = args.methods.split(",")
    presets = ["exact", *[p for p in sources if p != "exact"]]
    print(table(collect(sources, extra, methods, _seeds(args.seeds)), presets, methods))
    return 0


if __name__ == "__main__":
    sys.exit(main())

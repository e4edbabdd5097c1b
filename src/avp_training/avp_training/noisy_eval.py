"""The shipped intent CNN on samples seen through noisy sensing and the tracker (docs/results/sensing/README.md):
top-1 / top-3 per sensing preset on the held-out episodes of the model's splits (docs/intent_model.md) — the same
seeds, traffic and observer tour as the committed figures, only the observer's sensing differs — and, on the held-out
split, the Bayes observer that knows the driver model (:mod:`.oracle`) on the same samples.

    python -m avp_training.noisy_eval [--sensing exact,realistic,harsh] [--split test] [--episodes 60]
        [--workers 2] [--weights out/intent/intent_cnn.pt] [--json out/noisy_intent.json]

Under noise a sample is a *track* the observer's tracker confirmed; its label is the spot the vehicle it follows
takes (the simulator's truth, for the label only). Fewer samples exist than with exact sensing (missed and
not-yet-confirmed cars are not sampled), so beside each figure stands its n, and the exact figure of the same run.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def evaluate_presets(presets: list[str], split: str, episodes: int, workers: int, weights: str = "") -> list[dict]:
    """One row per preset: the CNN's top-1 / top-3 and its baseline; on the held-out split also the Bayes observer
    of :mod:`.oracle` beside the CNN on the same samples, per group (docs/intent_model.md). The CNN's weights from
    ``weights`` (default: the shipped ones)."""
    from avp_predictors.intent_model import IntentPredictor
    from avp_training.dataset import DataSpec, generate_split
    from avp_training.train import evaluate

    model = IntentPredictor.pretrained(path=weights or None).model
    rows = []
    for preset in presets:
        t0 = time.perf_counter()
        samples = generate_split(split, episodes, DataSpec(), workers=workers, progress=False, sensing=preset)
        m = evaluate(model, samples, with_baselines=True)
        row = {"sensing": preset, "split": split, "episodes": episodes, "n": m["n"], "top1": m["top1"],
               "top3": m["top3"], "nearest_ahead_top1": m.get("nearest_ahead", {}).get("top1"),
               "by": m.get("by", {})}
        if split == "test":  # the observer that knows the driver model, on the same (noisy) samples
            from avp_training.oracle import oracle_table
            from avp_training.train import model_logits, topk_hits

            row["bayes"] = oracle_table(samples, topk_hits(model_logits(model, samples), samples.labels, 1))
        rows.append({**row, "wall_s": round(time.perf_counter() - t0, 1)})
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sensing", default="exact,realistic,harsh")
    ap.add_argument("--split", default="test", choices=("test", "paper", "val"))
    ap.add_argument("--episodes", type=int, default=60)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--weights", default="", help="the intent CNN's weights (default: the shipped ones)")
    ap.add_argument("--json", default="")
    args = ap.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    rows = evaluate_presets(args.sensing.split(","), args.split, args.episodes, args.workers, args.weights)
    print("| split | sensing | samples | top-1 | top-3 | nearest-ahead top-1 | label a spot: top-1 | "
          "label none: top-1 |")
    print("|---|---|--:|--:|--:|--:|--:|--:|")
    for r in rows:
        spot, none = (r["by"].get(g, {}).get("top1", float("nan")) for g in ("label_spot", "label_none"))
        print(f"| {r['split']} ({r['episodes']} episodes) | {r['sensing']} | {r['n']} | {r['top1']:.3f} | "
              f"{r['top3']:.3f} | {r['nearest_ahead_top1']:.3f} | {spot:.3f} | {none:.3f} |")
    bayes = [r for r in rows if "bayes" in r]
    if bayes:
        print("\n| sensing | goal-directed parkers' group | n | Bayes observer top-1 | CNN top-1 |")
        print("|---|---|--:|--:|--:|")
        from avp_training.oracle import group_rows

        for r in bayes:
            print("\n".join(group_rows(r["bayes"], r["sensing"])))
            print(f"| {r['sensing']} | all: the observer on cruising and rolling cars, the CNN elsewhere | "
                  f"{r['bayes']['n']} | {r['bayes']['oracle_modelled_cnn_elsewhere']:.3f} | "
                  f"{r['bayes']['cnn_top1']:.3f} |")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({"args": vars(args), "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

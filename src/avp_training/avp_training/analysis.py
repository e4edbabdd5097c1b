"""Where the intent CNN's errors are (docs/intent_model.md, "What the error is made of").

On a split saved by ``avp train-intent`` / ``avp gen-intent-data`` (``OUT/data/test.npz``), with the shipped or
given weights: top-1 of the CNN and of the nearest-spot baseline on the samples whose label is a spot, by the
distance from the vehicle to that spot, and how often the CNN answers "none" there; the error budget (errors
per group — by label, distance, and speed below / above the parkers' final roll — and the top-1 of the whole set
were a group's errors all fixed: what any better predictor could gain there at most); then a hybrid rule (the
CNN, except that "none" becomes the nearest spot when it lies within X m) to test whether the distance feature
holds information the CNN leaves unused.

Usage: ``python -m avp_training.analysis out/intent_run1/data/test.npz [--weights FILE]``
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from avp_perception.core.pipeline import make_intent_predictor
from avp_training.dataset import Samples
from avp_training.train import baseline_scores, model_logits, topk_hits

BINS = ((0.0, 5.0), (5.0, 10.0), (10.0, 15.0), (15.0, 20.0), (20.0, 60.0))
SLOW_SPEED = 1.6  # m/s: above the parkers' final roll (0.8-1.5 m/s, traffic.py), below their cruise (2-4 m/s)


def error_table(samples: Samples, logits: list[np.ndarray]) -> dict:
    """Top-1 by distance to the labelled spot (label-is-spot samples), and the hybrid rule's top-1 per X."""
    y = samples.labels
    hit = topk_hits(logits, y, 1)
    near_scores = baseline_scores(samples, False)
    near_hit = topk_hits(near_scores, y, 1)
    pred = np.array([int(np.argmax(z)) for z in logits])
    near = np.array([int(np.argmax(b)) for b in near_scores])
    rows = [samples.features[samples.feature_rows(i)] for i in range(len(samples))]
    d_label = np.array([r[y[i], 1] if y[i] > 0 else np.nan for i, r in enumerate(rows)])
    d_near = np.array([r[near[i], 1] if near[i] > 0 else np.inf for i, r in enumerate(rows)])
    spot = y > 0
    out = {"n": int(len(y)), "top1": float(hit.mean()), "label_spot_top1": float(hit[spot].mean()),
           "label_none_top1": float(hit[~spot].mean()), "by_distance": [], "hybrid": {}}
    for lo, hi in BINS:
        m = spot & (d_label >= lo) & (d_label < hi)
        if m.any():
            out["by_distance"].append({"from_m": lo, "to_m": hi, "n": int(m.sum()), "cnn": float(hit[m].mean()),
                                       "nearest": float(near_hit[m].mean()),
                                       "cnn_says_none": float((pred[m] == 0).mean())})
    # the error budget: each group's errors and the top-1 the whole set would reach were they all fixed
    slow = samples.speed < SLOW_SPEED
    groups = [("label none", ~spot)] + [
        (f"label a spot {lo:.0f}-{hi:.0f} m away", spot & (d_label >= lo) & (d_label < hi)) for lo, hi in BINS]
    groups += [(f"{who}, {how}", mask & sp) for who, mask in (("label a spot", spot), ("label none", ~spot))
               for how, sp in ((f"slower than {SLOW_SPEED:g} m/s", slow), ("faster", ~slow))]
    out["error_budget"] = [{"group": name, "n": int(m.sum()), "top1": float(hit[m].mean()) if m.any() else 0.0,
                            "errors": int((~hit & m).sum()),
                            "top1_if_fixed": float((hit | m).mean())} for name, m in groups]
    for x in (2.0, 3.0, 4.0, 5.0, 6.0, 8.0):
        mixed = np.where((pred == 0) & (d_near < x), near, pred)
        out["hybrid"][x] = float((mixed == y).mean())
    return out


def load_split_and_logits(prog: str, description: str, argv: list[str] | None
                          ) -> tuple[Samples, list[np.ndarray], str]:
    """The command line of the analysis tools (``split [--weights FILE]``): the saved split, the intent CNN's
    logits on it (shipped or given weights, 1 torch thread) and the line saying which weights."""
    ap = argparse.ArgumentParser(prog=prog, description=description)
    ap.add_argument("split", help="a saved split (.npz)")
    ap.add_argument("--weights", default="", help="intent CNN state dict (default: the shipped weights)")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    samples = Samples.load(args.split)
    intent, info = make_intent_predictor(None, weights=args.weights)
    return samples, model_logits(intent.model, samples), info


def main(argv: list[str] | None = None) -> int:
    samples, logits, info = load_split_and_logits("python -m avp_training.analysis",
                                                  __doc__.split("\n")[0], argv)
    t = error_table(samples, logits)
    print(f"{info}; {t['n']} samples: top-1 {t['top1']:.3f} (label a spot {t['label_spot_top1']:.3f}, "
          f"label none {t['label_none_top1']:.3f})")
    print("| distance to the labelled spot | n | CNN top-1 | nearest top-1 | CNN says none |")
    print("|---|--:|--:|--:|--:|")
    for r in t["by_distance"]:
        print(f"| {r['from_m']:.0f}–{r['to_m']:.0f} m | {r['n']} | {r['cnn']:.3f} | {r['nearest']:.3f} | "
              f"{r['cnn_says_none']:.3f} |")
    print(f"| group | n | CNN top-1 | errors | top-1 of all {t['n']} were they fixed |")
    print("|---|--:|--:|--:|--:|")
    for r in t["error_budget"]:
        print(f"| {r['group']} | {r['n']} | {r['top1']:.3f} | {r['errors']} | {r['top1_if_fixed']:.3f} |")
    print("hybrid (CNN; its 'none' -> the nearest spot within X m): "
          + ", ".join(f"X = {x:g} m: {v:.3f}" for x, v in t["hybrid"].items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The trajectory predictors open loop on tracked histories (docs/results/sensing/README.md): minADE / minFDE over
4 s of the learned transformer, the Bézier curves and constant velocity on the held-out sets of the model card
(docs/trajectory_model.md: the same seeds, traffic and observer tour), per sensing preset.

    python -m avp_trajectory_training.noisy_eval [--sensing exact,realistic,harsh] [--test 50] [--paper 60]
        [--workers 2] [--weights out/trajectory/trajectory_transformer.pt] [--json out/noisy_trajectory.json]

Under noise a sample is a track the observer's tracker confirmed that follows a traffic car: its history is the
track's (shorter for a young track, noisy), its future and goal the car's from the simulator's log (labels only),
its intentions the shipped intent CNN's on what the observer saw. The exact rows reproduce the model card's
figures sample for sample, which checks the pipeline.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

SETS = ("test", "paper")
COLUMNS = (("oracle_learned", "learned (true goal)"), ("oracle_bezier", "Bézier (true goal)"),
           ("intent_learned", "learned (intent CNN)"), ("intent_bezier", "Bézier (intent CNN)"),
           ("cv", "constant velocity"))


def evaluate_presets(presets: list[str], episodes: dict[str, int], workers: int, weights: str = "") -> list[dict]:
    """One row per (preset, set, group): n and [minADE, minFDE] of each predictor; the learned model's weights
    from the file ``weights`` names (a path or a name in the package's models/; default: the shipped ones)."""
    from avp_predictors.learned_prediction import load_model, weights_path
    from avp_trajectory_training.data import generate
    from avp_trajectory_training.train import evaluate

    model = load_model(weights_path(weights))
    rows = []
    for preset in presets:
        for name in SETS:
            if not episodes.get(name):
                continue
            t0 = time.perf_counter()
            samples = generate(name, episodes[name], workers=workers, progress=False, sensing=preset)
            m = evaluate(model, samples)
            wall = round(time.perf_counter() - t0, 1)
            for group, e in m.items():
                if isinstance(e, dict) and e.get("n"):
                    rows.append({"sensing": preset, "set": name, "episodes": episodes[name], "group": group,
                                 "n": e["n"], **{k: e[k] for k, _ in COLUMNS}, "wall_s": wall})
    return rows


def table(rows: list[dict]) -> str:
    def f(v) -> str:
        return f"{v[0]:.2f} / {v[1]:.2f}" if v else "–"

    out = ["| set | group | sensing | n | " + " | ".join(t for _, t in COLUMNS) + " |",
           "|---|---|---|--:|" + "--:|" * len(COLUMNS)]
    for r in sorted(rows, key=lambda r: (SETS.index(r["set"]), r["group"] != "all", r["group"])):
        out.append(f"| {r['set']} ({r['episodes']} episodes) | {r['group']} | {r['sensing']} | {r['n']} | "
                   + " | ".join(f(r[k]) for k, _ in COLUMNS) + " |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sensing", default="exact,realistic,harsh")
    ap.add_argument("--test", type=int, default=50, help="held-out traffic episodes (the model card's 50)")
    ap.add_argument("--paper", type=int, default=60, help="paper-lot scenarios (the model card's 60)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--weights", default="", help="the learned model's weights (default: the shipped ones)")
    ap.add_argument("--json", default="")
    args = ap.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    rows = evaluate_presets(args.sensing.split(","), {"test": args.test, "paper": args.paper}, args.workers,
                            args.weights)
    print(table(rows))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({"args": vars(args), "rows": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

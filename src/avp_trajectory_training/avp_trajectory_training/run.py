"""``avp train-trajectory``: the learned trajectory predictor from scratch on this machine (docs/trajectory_model.md).

Generates the data (:mod:`.trajectory`: training / validation / held-out test episodes on the DLP-derived and
random lots, and the paper-lot test set), trains, evaluates learned vs Bezier vs constant velocity on both test
sets (:func:`~.trajectory.evaluate`) and writes the weights (``avp_predictors/models/trajectory_transformer.pt``
for ``--scale full`` unless ``--weights`` says otherwise) with a JSON card beside them. Same seed, thread count
and library versions => the same weights. Model card: docs/trajectory_model.md.
"""

from __future__ import annotations

import argparse
import time

SCALES = {
    # episodes per split: train, val, test, paper; epochs
    "full": (360, 24, 50, 60, 12),
    "dev": (40, 4, 8, 8, 8),
    "tiny": (2, 1, 1, 1, 1),
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    from avp_training.run import add_train_arguments

    add_train_arguments(p, SCALES, "out/trajectory", "trajectory_transformer.pt", "dev/tiny: development runs")


def cmd_train_trajectory(args: argparse.Namespace) -> int:
    import numpy as np
    import torch

    from avp_predictors.learned_prediction import default_weights_path, save_model
    from avp_training.run import (
        card_provenance,
        finish_run,
        load_splits,
        save_weights,
        start_run,
    )
    from avp_trajectory_training.train import (
        TRAJ_SEED0,
        TrajDataSpec,
        TrajSamples,
        TrajTrainConfig,
        evaluate,
        generate,
        train,
    )

    def log(msg: str) -> None:
        print(msg, flush=True)

    t_start = time.monotonic()
    episodes, out, data_dir, weights, config = start_run("train-trajectory", args, SCALES, default_weights_path(),
                                                         "trajectory_transformer.pt", TrajTrainConfig(), log)
    spec = TrajDataSpec()
    torch.set_num_threads(args.threads)
    sets, timings = load_splits("train-trajectory", episodes, spec, args, data_dir, generate, TrajSamples.load, log)
    t0 = time.monotonic()
    model, history = train(sets["train"], sets["val"], config, progress=not args.quiet, log=log)
    timings["train_s"] = time.monotonic() - t0
    t0 = time.monotonic()
    torch.set_num_threads(1)
    metrics = {name: evaluate(model, sets[name]) for name in ("test", "paper")}
    timings["eval_s"] = time.monotonic() - t0
    timings["total_s"] = time.monotonic() - t_start
    save_weights(save_model, model, weights, out, "trajectory_transformer.pt")
    card = {
        "model": "TrajectoryTransformer (ParkPredict+ decoder with intent cross-attention), 0.4 s step, "
                 "10 history / 10 future poses, 100 x 100 px BEV",
        **card_provenance("train-trajectory", model, weights, args.scale, args.train_sensing),
        "seeds": {name: [TRAJ_SEED0[name], TRAJ_SEED0[name] + n - 1] for name, n in episodes.items()},
        "data": {name: {"episodes": n, "samples": len(sets[name]),
                        "goal_kinds": np.bincount(sets[name].goal_kind, minlength=3).tolist()}
                 for name, n in episodes.items()},
        "data_spec": repr(spec),
    }
    return finish_run("train-trajectory", card, config, history, metrics, timings, weights, out, log,
                      summary_table(metrics))


def summary_table(metrics: dict) -> str:
    """minADE / minFDE (m) table of :func:`~.trajectory.evaluate` results."""

    def f(v) -> str:
        return f"{v[0]:.2f} / {v[1]:.2f}" if v else "-"

    rows = ["| test set | group | n | learned (true goal) | Bezier (true goal) | learned (intent CNN) | "
            "Bezier (intent CNN) | constant velocity |", "|---|---|---|---|---|---|---|---|"]
    for name, m in metrics.items():
        for g, e in m.items():
            if not isinstance(e, dict) or not e.get("n"):
                continue
            rows.append(f"| {name} | {g} | {e['n']} | {f(e['oracle_learned'])} | {f(e['oracle_bezier'])} | "
                        f"{f(e['intent_learned'])} | {f(e['intent_bezier'])} | {f(e['cv'])} |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    """``python -m avp_trajectory_training.run ...`` (the same as ``avp train-trajectory ...``)."""
    parser = argparse.ArgumentParser(prog="avp train-trajectory")
    add_arguments(parser)
    return cmd_train_trajectory(parser.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())

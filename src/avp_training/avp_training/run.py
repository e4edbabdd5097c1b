"""``avp train-intent`` and ``avp gen-intent-data``: the intent CNN from scratch on this machine (docs/intent_model.md).

``avp train-intent`` generates the data (training, validation and test episodes on the DLP-derived and random
lots, and the paper-lot test set), trains (:mod:`.train`), evaluates on both test sets beside the
nearest-spot baselines, and writes the weights (``avp_predictors/models/intent_cnn.pt`` unless ``--weights``
says otherwise) with a JSON card beside them (data, sizes, command, commit, wall times, accuracy). Same seed,
same thread count and same library versions => the same weights. docs/intent_model.md is the model card.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from avp_common.provenance import source_commit

SCALES = {
    # episodes per split: train, val, test, paper; max epochs
    "full": (320, 30, 60, 160, 6),
    "quick": (40, 8, 10, 20, 2),
    "tiny": (4, 2, 2, 3, 1),
}


def add_train_arguments(p: argparse.ArgumentParser, scales: dict = SCALES, out: str = "out/intent",
                        weights_file: str = "intent_cnn.pt", small: str = "quick/tiny: smoke runs") -> None:
    """The arguments every ``avp train-*`` command takes: data and epoch budget (``scales``, whose ``full`` makes
    the shipped weights ``weights_file``), work folder, threads, seed, data reuse."""
    p.add_argument("--scale", choices=sorted(scales), default="full",
                   help=f"data and epoch budget (full: the shipped weights; {small})")
    p.add_argument("--out", default=out, help="work folder: data, weights copy, metrics")
    p.add_argument("--weights", default=None, help=f"where to write the weights (default: the package's "
                   f"models/{weights_file} for --scale full, else OUT/{weights_file})")
    p.add_argument("--workers", type=int, default=2, help="processes generating episodes")
    p.add_argument("--threads", type=int, default=2, help="torch threads for training")
    p.add_argument("--seed", type=int, default=0, help="training seed (data seeds are fixed per split)")
    p.add_argument("--epochs", type=int, default=None, help="override the scale's maximum number of epochs")
    p.add_argument("--reuse-data", action="store_true", help="reuse OUT/data/*.npz made with the same settings")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--train-sensing", default="exact", type=sensing_list,
                   help="sensing presets the training and validation episodes are seen through, comma-separated: "
                        "exact (the shipped weights), or e.g. exact,realistic: the same episodes once exactly and "
                        "once through the noisy sensor and the tracker (docs/perception.md); test sets stay exact")


def sensing_list(text: str) -> tuple[str, ...]:
    """``--train-sensing``: comma-separated presets of avp_sensing.noisy (or exact), each once."""
    from avp_sensing.noisy import PRESETS

    names = tuple(dict.fromkeys(t.strip() for t in text.split(",") if t.strip()))
    bad = [n for n in names if n != "exact" and n not in PRESETS]
    if not names or bad:
        raise argparse.ArgumentTypeError(f"expected exact or presets of {sorted(PRESETS)}, got {text!r}")
    return names


def add_intent_arguments(p: argparse.ArgumentParser) -> None:
    """``avp train-intent``'s arguments: :func:`add_train_arguments`, ``--features`` and ``--device``."""
    add_train_arguments(p)
    p.add_argument("--features", type=int, default=None,
                   help="train on the first N features of FEATURE_NAMES (default 5: ParkPredict+'s; 12 adds the "
                        "motion features, docs/intent_model.md)")
    p.add_argument("--device", default="cpu",
                   help="torch device of the training steps, e.g. cuda (the shipped weights: cpu; another device "
                        "gives other weights)")


def add_gen_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("split", choices=["train", "val", "test", "paper"])
    p.add_argument("--episodes", type=int, required=True)
    p.add_argument("--out", required=True, help="output .npz")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--quiet", action="store_true")


def cached_split(prog: str, name: str, n: int, spec, args, data_dir: Path, generate, load, log):
    """Split ``name`` of ``n`` episodes, made by ``generate(name, n, spec, workers=..., progress=...)`` and saved
    under ``data_dir`` — or, with ``--reuse-data``, read back with ``load`` when it was made with the same
    settings. Returns (samples, seconds spent generating). Shared by ``avp train-intent`` and
    ``avp train-trajectory``."""
    path, meta = data_dir / f"{name}.npz", data_dir / f"{name}.json"
    key = {"split": name, "episodes": n, "spec": repr(spec)}
    sensing = split_sensing(name, args)
    if sensing != ("exact",):
        key["sensing"] = list(sensing)
    if args.reuse_data and path.is_file() and meta.is_file() and json.loads(meta.read_text()) == key:
        log(f"[{prog}] reusing {path}")
        return load(path), 0.0
    t0 = time.monotonic()
    parts = [generate(name, n, spec, workers=args.workers, progress=not args.quiet, sensing=preset)
             for preset in sensing]
    s = parts[0] if len(parts) == 1 else type(parts[0]).concat(parts)
    dt = time.monotonic() - t0
    s.save(path)
    meta.write_text(json.dumps(key))
    log(f"[{prog}] {name}: {n} episodes -> {len(s)} samples in {dt:.0f} s")
    return s, dt


SPLITS = ("train", "val", "test", "paper")


def split_sensing(name: str, args: argparse.Namespace) -> tuple[str, ...]:
    """The presets split ``name`` is seen through: ``--train-sensing`` for training and validation (the best epoch is
    chosen on the same mix), exact for the test sets (the model card's figures; noisy ones by the noisy_eval
    modules)."""
    return tuple(getattr(args, "train_sensing", None) or ("exact",)) if name in ("train", "val") else ("exact",)


def start_run(prog: str, args: argparse.Namespace, scales: dict, default_weights: Path, file_name: str, base_config,
              log):
    """The common head of ``avp train-intent`` / ``avp train-trajectory``: ``scales[args.scale]``'s episodes per split
    ({split: n}), OUT and OUT/data, where the weights go (``--weights``, else ``default_weights`` for ``--scale
    full``, else OUT/``file_name``) and ``base_config`` with ``--seed``, ``--threads`` and ``--epochs``."""
    *sizes, epochs = scales[args.scale]
    episodes = dict(zip(SPLITS, sizes, strict=True))
    out = Path(args.out)
    data_dir = out / "data"
    data_dir.mkdir(parents=True, exist_ok=True)
    weights = Path(args.weights) if args.weights else (default_weights if args.scale == "full" else out / file_name)
    config = replace(base_config, seed=args.seed, threads=args.threads,
                     epochs=args.epochs if args.epochs is not None else epochs)
    log(f"[{prog}] scale {args.scale}: episodes "
        + ", ".join(f"{k} {n}" for k, n in episodes.items())
        + f"; {args.workers} workers, {args.threads} torch threads; load average {os.getloadavg()[0]:.2f}")
    return episodes, out, data_dir, weights, config


def load_splits(prog: str, episodes: dict[str, int], spec, args, data_dir: Path, generate, load, log):
    """Every split by :func:`cached_split`; returns ({split: samples}, {"data_<split>_s": seconds})."""
    sets, timings = {}, {}
    for name, n in episodes.items():
        sets[name], timings[f"data_{name}_s"] = cached_split(prog, name, n, spec, args, data_dir, generate, load, log)
    return sets, timings


def save_weights(save, model, weights: Path, out: Path, file_name: str) -> None:
    """``save(model, path)`` to ``weights`` and, when that is elsewhere, to OUT/``file_name`` too."""
    weights.parent.mkdir(parents=True, exist_ok=True)
    save(model, weights)
    if weights.resolve() != (out / file_name).resolve():
        save(model, out / file_name)


def card_provenance(prog: str, model, weights: Path, scale: str, train_sensing=("exact",)) -> dict:
    """The model card fields every training command records: size, command line, commit, scale, the sensing the
    training and validation episodes were seen through."""
    return {
        "parameters": int(sum(p.numel() for p in model.parameters())),
        "weights_bytes": weights.stat().st_size,
        "command": f"avp {prog} " + " ".join(shlex.quote(a) for a in sys.argv[2:]) if len(sys.argv) > 1 else "",
        "commit": source_commit(__file__),
        "scale": scale,
        "train_sensing": list(train_sensing),
    }


def card_machine() -> dict:
    """Machine and library versions of a training run."""
    import torch

    return {"cpus": os.cpu_count(), "python": platform.python_version(), "torch": torch.__version__,
            "numpy": np.__version__, "load_average_end": round(os.getloadavg()[0], 2)}


def write_card(prog: str, card: dict, weights: Path, out: Path, log) -> None:
    """Write the card beside the weights and as OUT/metrics.json."""
    card_path = weights.with_suffix(".json")
    card_path.write_text(json.dumps(card, indent=1))
    (out / "metrics.json").write_text(json.dumps(card, indent=1))
    log(f"[{prog}] wrote {weights} ({card['weights_bytes'] / 1e6:.2f} MB) and {card_path}")


def finish_run(prog: str, card: dict, config, history, metrics: dict, timings: dict[str, float], weights: Path,
               out: Path, log, table: str) -> int:
    """Complete ``card`` with what every training run records (its config, learning curve, metrics, timings and
    machine), write it beside the weights, log the summary ``table`` and the wall time; exit code 0."""
    card.update({"train_config": asdict(config), "history": history, "metrics": metrics,
                 "timings_s": {k: round(v, 1) for k, v in timings.items()}, "machine": card_machine()})
    write_card(prog, card, weights, out, log)
    log(table)
    log_wall_time(prog, timings, log)
    return 0


def log_wall_time(prog: str, timings: dict[str, float], log) -> None:
    log(f"[{prog}] wall time {timings['total_s'] / 60:.1f} min "
        f"(data {sum(v for k, v in timings.items() if k.startswith('data_')) / 60:.1f}, "
        f"training {timings['train_s'] / 60:.1f}, evaluation {timings['eval_s'] / 60:.1f})")


def cmd_train_intent(args: argparse.Namespace) -> int:
    import torch

    from avp_predictors.intent_model import FEATURE_NAMES, default_weights_path
    from avp_training.dataset import DataSpec, Samples, generate_split
    from avp_training.train import TrainConfig, evaluate, train

    def log(msg: str) -> None:
        print(msg, flush=True)

    t_start = time.monotonic()
    episodes, out, data_dir, weights, config = start_run("train-intent", args, SCALES, default_weights_path(),
                                                         "intent_cnn.pt", TrainConfig(device=args.device), log)
    if args.features is not None:
        config = replace(config, n_features=args.features)
    spec = DataSpec()
    sets, timings = load_splits("train-intent", episodes, spec, args, data_dir, generate_split, Samples.load, log)
    t0 = time.monotonic()
    model, history = train(sets["train"], sets["val"], config, progress=not args.quiet, log=log)
    timings["train_s"] = time.monotonic() - t0
    t0 = time.monotonic()
    metrics = {name: evaluate(model, sets[name], threads=args.threads, with_baselines=True)
               for name in ("test", "paper", "val")}
    timings["eval_s"] = time.monotonic() - t0
    timings["total_s"] = time.monotonic() - t_start
    save_weights(lambda m, path: torch.save(m.state_dict(), path), model, weights, out, "intent_cnn.pt")
    card = {
        "model": "SmallRegularizedCNN (ParkPredict+), 100 x 100 px BEV at 0.4 m/px, "
                 f"{config.n_features} features: {', '.join(FEATURE_NAMES[: config.n_features])}",
        **card_provenance("train-intent", model, weights, args.scale, args.train_sensing),
        "data": {name: {"episodes": n, "samples": len(sets[name]),
                        "mean_options": float(sets[name].n_candidates.mean() + 1) if len(sets[name]) else 0.0,
                        "none_share": float((sets[name].labels == 0).mean()) if len(sets[name]) else 0.0}
                 for name, n in episodes.items()},
        "data_spec": {k: (v if not hasattr(v, "__dataclass_fields__") else asdict(v)) for k, v in asdict(spec).items()},
    }
    return finish_run("train-intent", card, config, history, metrics, timings, weights, out, log,
                      summary_table(metrics))


def summary_table(metrics: dict) -> str:
    rows = ["| test set | instances | mean options | CNN top-1 | CNN top-3 | nearest ahead top-1 | top-3 | "
            "nearest top-1 | top-3 |", "|---|---|---|---|---|---|---|---|---|"]
    for name in ("test", "paper"):
        m = metrics[name]
        if not m.get("n"):
            continue
        rows.append(f"| {name} | {m['n']} | {m['mean_options']:.2f} | {m['top1']:.3f} | {m['top3']:.3f} | "
                    f"{m['nearest_ahead']['top1']:.3f} | {m['nearest_ahead']['top3']:.3f} | "
                    f"{m['nearest']['top1']:.3f} | {m['nearest']['top3']:.3f} |")
    return "\n".join(rows)


def cmd_gen_intent_data(args: argparse.Namespace) -> int:
    from avp_training.dataset import DataSpec, generate_split

    t0 = time.monotonic()
    s = generate_split(args.split, args.episodes, DataSpec(), workers=args.workers, progress=not args.quiet)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    s.save(args.out)
    print(f"[gen-intent-data] {args.split}: {args.episodes} episodes -> {len(s)} samples in "
          f"{time.monotonic() - t0:.0f} s; wrote {args.out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m avp_training.run train-intent|gen-intent-data ...`` (the same as ``avp ...``)."""
    parser = argparse.ArgumentParser(prog="avp")
    sub = parser.add_subparsers(dest="cmd", required=True)
    add_intent_arguments(sub.add_parser("train-intent", help="train the intent CNN from scratch"))
    add_gen_arguments(sub.add_parser("gen-intent-data", help="generate intent samples of one split"))
    args = parser.parse_args(argv)
    return cmd_train_intent(args) if args.cmd == "train-intent" else cmd_gen_intent_data(args)


if __name__ == "__main__":
    raise SystemExit(main())

"""Training and evaluation of the intent CNN of §V-A (the recipe and its reasons: docs/intent_model.md).

**Model.** :class:`~avp_predictors.intent_model.SmallRegularizedCNN` (ParkPredict+, reference sheet §1.4)
on the 100 x 100 px BEVs; one logit per option of an instance (a vehicle at one step): [none, candidates].

**Loss.** The grouped negative log-likelihood of the true option under the probabilities the pipeline uses at
inference (sigmoid of each logit divided by their sum over the instance, sheet §1.5):

    L = -log sigma(z_y) + log sum_j w_j sigma(z_j)

ParkPredict+ trains each candidate with an independent BCE; its sigmoids are only normalised afterwards, so
nothing makes them a good distribution over one vehicle's options, while this loss trains exactly the
eta_k,i that eq. (8) and the planner consume (top-1 is the arg-max of the same numbers). Instances with more
than ``max_candidates`` candidates are trained on the true one, "none" and a random subset of the others,
whose sigmoids get the weight w = (number of negatives) / (number kept), so the sum stays unbiased.

**Recipe.** AdamW (lr 1e-3, as ParkPredict+), cosine decay, batches of about ``batch_images`` images, fixed
seeds, ``torch.set_num_threads``; dropout only in the fully connected head during training (the conv-block
dropout of the architecture is set to 0 for speed: it costs a third of the time on this CPU, and the data are
plentiful; dropout has no weights, so the saved state dict is the architecture's). Early stopping on the
top-1 accuracy of a validation split of its own seeds — never the test set (ParkPredict+ stopped on its test
scene, sheet §1.7).

**Evaluation** (:func:`evaluate`): grouped top-1 / top-3 accuracy per instance over [none, candidates],
logits computed by :meth:`IntentPredictor.logits` — the inference path of the pipeline — beside the
*nearest-spot-ahead* baseline (:func:`baseline_scores`): the nearest candidate whose centre lies ahead of the
car (cos > 0), "none" when no candidate is ahead; its ranking is the candidates ahead by distance, then
"none", then those behind by distance. The plain nearest candidate is reported too.
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np
import torch
import torch.nn.functional as F

from avp_belief_map.bev import BEVConfig, VehicleBEV
from avp_predictors.intent_model import IntentPredictor, SmallRegularizedCNN, receptive_field
from avp_training.dataset import LOT_NAMES, Samples


@dataclass(frozen=True)
class TrainConfig:
    seed: int = 0
    epochs: int = 8  # at most
    patience: int = 3  # epochs without a better validation top-1
    lr: float = 1e-3
    lr_final: float = 0.05  # cosine decay to this fraction of lr
    weight_decay: float = 1e-4
    batch_images: int = 256
    max_candidates: int = 12
    conv_dropout: float = 0.0
    fc_dropout: float = 0.2
    threads: int = 2
    n_features: int = 5  # the first n of FEATURE_NAMES: 5 = ParkPredict+'s; N_FEATURES adds the motion features
    device: str = "cpu"  # torch device of the training steps ("cuda" where there is one); evaluation runs on the CPU


# ------------------------------------------------------------------------------------------- batches


def _instance_options(samples: Samples, i: int, rng: np.random.Generator | None, max_candidates: int
                      ) -> tuple[np.ndarray, np.ndarray, int]:
    """Candidate positions (0-based within instance i) used, their sum weights, and the target position in
    [none] + used (0 = none)."""
    k = int(samples.cand_offsets[i + 1] - samples.cand_offsets[i])
    y = int(samples.labels[i])
    cand = np.arange(k)
    w = np.ones(k)
    if rng is not None and k > max_candidates:
        neg = cand[cand != y - 1]
        n_keep = max_candidates - (1 if y > 0 else 0)
        keep = np.sort(rng.choice(neg, size=n_keep, replace=False))
        cand = np.sort(np.concatenate([keep, [y - 1]])) if y > 0 else keep
        w = np.where(cand == y - 1, 1.0, len(neg) / n_keep)
    target = 0 if y == 0 else 1 + int(np.nonzero(cand == y - 1)[0][0])
    return cand, w, target


def make_batch(samples: Samples, idx: np.ndarray, rng: np.random.Generator | None, max_candidates: int,
               used: int | None = None):
    """Images (B, 3, used, used) float in [0, 1] (channels-last), features (B, 5), and per instance its row
    range, option weights and target option. ``used``: keep only the first rows / cols of the images — the
    network output depends on the first 94 of 100 (its floor-mode pools never read the rest), so training on
    the crop computes the same outputs with 12 % fewer pixels."""
    images, feats, spans, weights, targets = [], [], [], [], []
    row = 0
    for i in idx:
        i = int(i)
        cand, w, target = _instance_options(samples, i, rng, max_candidates)
        marked = samples.candidate_images(i)[cand]
        images.append(samples.images[i][None])
        images.append(marked)
        f = samples.features[samples.feature_rows(i)]
        feats.append(np.concatenate([f[:1], f[1:][cand]]))
        n = 1 + len(cand)
        spans.append((row, row + n))
        weights.append(np.concatenate([[1.0], w]))
        targets.append(target)
        row += n
    arr = np.concatenate(images)
    if used is not None:
        arr = arr[:, :used, :used]
    x = torch.from_numpy(arr).permute(0, 3, 1, 2).float().mul_(1.0 / 255.0)
    x = x.contiguous(memory_format=torch.channels_last)
    return x, torch.from_numpy(np.concatenate(feats).astype(np.float32)), spans, weights, targets


def grouped_loss(logits: torch.Tensor, spans, weights, targets) -> torch.Tensor:
    """Mean over instances of -log sigma(z_y) + log sum_j w_j sigma(z_j) (module docstring)."""
    g = len(spans)
    m = max(b - a for a, b in spans)
    pad = torch.full((g, m), -math.inf)
    logw = torch.full((g, m), 0.0)
    index = torch.zeros(logits.shape[0], dtype=torch.long)
    for r, (a, b) in enumerate(spans):
        index[a:b] = r * m + torch.arange(b - a)
        logw.view(-1)[r * m:r * m + b - a] = torch.from_numpy(np.log(weights[r]).astype(np.float32))
    dev = logits.device
    pad, logw, index = pad.to(dev), logw.to(dev), index.to(dev)
    ls = F.logsigmoid(logits)
    mat = pad.view(-1).index_put((index,), ls).view(g, m)
    lse = torch.logsumexp(mat + logw, dim=1)
    tgt = torch.tensor([r * m + t for r, t in enumerate(targets)], device=dev)
    return (lse - mat.view(-1)[tgt]).mean()


def _batches(samples: Samples, order: np.ndarray, budget: int) -> list[np.ndarray]:
    sizes = np.minimum(samples.n_candidates, 10**9) + 1
    out, cur, n = [], [], 0
    for i in order:
        cur.append(i)
        n += int(sizes[i])
        if n >= budget:
            out.append(np.array(cur))
            cur, n = [], 0
    if cur:
        out.append(np.array(cur))
    return out


# ------------------------------------------------------------------------------------------ training


def build_model(config: TrainConfig, size_px: int = 100) -> SmallRegularizedCNN:
    torch.manual_seed(config.seed)
    model = SmallRegularizedCNN(size_px, n_features=config.n_features, dropout=config.fc_dropout)
    for block in model.conv:
        block[2].p = config.conv_dropout
    return model


def train(train_set: Samples, val_set: Samples, config: TrainConfig = TrainConfig(), progress: bool = True,
          log=print) -> tuple[SmallRegularizedCNN, list[dict]]:
    """Train from scratch (module docstring); returns the best model (by validation top-1) and the history."""
    from tqdm import tqdm

    torch.set_num_threads(config.threads)
    rng = np.random.default_rng(config.seed)
    model = build_model(config, train_set.images.shape[1]).to(config.device, memory_format=torch.channels_last)
    field, stride = receptive_field()
    used = stride * (model.out_size - 1) + field  # input rows / cols the output depends on
    opt = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    n_batches = len(_batches(train_set, np.arange(len(train_set)), config.batch_images))
    total = max(1, n_batches * config.epochs)
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda s: config.lr_final + (1 - config.lr_final) * 0.5 * (1 + math.cos(math.pi * min(s, total) / total)))
    history: list[dict] = []
    best, best_state, bad = -1.0, None, 0
    for epoch in range(config.epochs):
        model.train()
        batches = _batches(train_set, rng.permutation(len(train_set)), config.batch_images)
        t0 = time.monotonic()
        losses = []
        bar = tqdm(batches, desc=f"epoch {epoch + 1}/{config.epochs}", disable=not progress, dynamic_ncols=True,
                   mininterval=1.0)
        for idx in bar:
            x, f, spans, w, tg = make_batch(train_set, idx, rng, config.max_candidates, used)
            loss = grouped_loss(model(x.to(config.device), f.to(config.device)), spans, w, tg)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            losses.append(float(loss.detach()))
            bar.set_postfix(loss=f"{np.mean(losses[-50:]):.3f}")
        bar.close()
        val = evaluate(copy.deepcopy(model).cpu(), val_set, threads=config.threads)
        rec = {"epoch": epoch + 1, "train_loss": float(np.mean(losses)), "val_top1": val["top1"],
               "val_top3": val["top3"], "val_nll": val["nll"], "seconds": round(time.monotonic() - t0, 1)}
        history.append(rec)
        log(f"[train-intent] epoch {epoch + 1}: loss {rec['train_loss']:.4f}  val top-1 {val['top1']:.4f}  "
            f"top-3 {val['top3']:.4f}  nll {val['nll']:.4f}  ({rec['seconds']} s)")
        if val["top1"] > best:
            best, best_state, bad = val["top1"], copy.deepcopy(model.state_dict()), 0
        else:
            bad += 1
            if bad >= config.patience:
                log(f"[train-intent] early stop: no better validation top-1 for {bad} epochs")
                break
    model.load_state_dict(best_state)
    model = model.to("cpu", memory_format=torch.contiguous_format).eval()
    return model, history


# ---------------------------------------------------------------------------------------- evaluation


def vehicle_bevs(samples: Samples, idx) -> list[VehicleBEV]:
    """The stored instances as :class:`VehicleBEV` (what :meth:`IntentPredictor.logits` takes)."""
    out = []
    for i in idx:
        i = int(i)
        c0, c1 = int(samples.cand_offsets[i]), int(samples.cand_offsets[i + 1])
        out.append(VehicleBEV(vehicle_id=int(samples.vehicle[i]), pose=np.zeros(3), speed=float(samples.speed[i]),
                              image=samples.images[i], candidate_idx=np.arange(c1 - c0),
                              candidate_spot_ids=samples.candidate_spot_ids[c0:c1],
                              candidate_images=samples.candidate_images(i),
                              candidate_boxes=samples.candidate_boxes[c0:c1]))
    return out


def model_logits(model: SmallRegularizedCNN, samples: Samples, chunk: int = 64, threads: int = 1) -> list[np.ndarray]:
    """Per instance the logits over [none, candidates], through the inference path (incremental mode)."""
    torch.set_num_threads(threads)
    pred = IntentPredictor(None, BEVConfig(size_px=samples.images.shape[1]), model=copy.deepcopy(model).eval())
    out: list[np.ndarray] = []
    for s in range(0, len(samples), chunk):
        idx = range(s, min(len(samples), s + chunk))
        z = pred.logits(vehicle_bevs(samples, idx), [samples.features[samples.feature_rows(i)] for i in idx])
        start = 0
        for i in idx:
            n = int(samples.cand_offsets[i + 1] - samples.cand_offsets[i]) + 1
            out.append(z[start:start + n])
            start += n
    return out


def baseline_scores(samples: Samples, ahead_only: bool = True) -> list[np.ndarray]:
    """Scores of the nearest-spot baselines over [none, candidates] (module docstring), from the features
    (cos to the spot centre, distance)."""
    out = []
    for i in range(len(samples)):
        f = samples.features[samples.feature_rows(i)]
        cos, dist = f[1:, 0].astype(float), f[1:, 1].astype(float)
        if ahead_only:
            s = np.where(cos > 0.0, 1000.0 - dist, -dist)
            out.append(np.concatenate([[0.0], s]))
        else:
            out.append(np.concatenate([[-1e9], -dist]))
    return out


def topk_hits(scores: list[np.ndarray], labels: np.ndarray, k: int) -> np.ndarray:
    """Whether the label is among the k best options (ties: the lower index ranks first)."""
    hits = np.zeros(len(scores), dtype=bool)
    for i, s in enumerate(scores):
        order = np.argsort(-np.asarray(s), kind="stable")
        hits[i] = int(labels[i]) in order[:k]
    return hits


def _nll(logits: list[np.ndarray], labels: np.ndarray) -> float:
    tot = 0.0
    for z, y in zip(logits, labels, strict=True):
        s = 1.0 / (1.0 + np.exp(-np.asarray(z, dtype=float)))
        tot += -math.log(max(s[int(y)] / s.sum(), 1e-12))
    return tot / max(1, len(labels))


def evaluate(model: SmallRegularizedCNN, samples: Samples, threads: int = 1, with_baselines: bool = False) -> dict:
    """Grouped top-1 / top-3 and NLL of the model (and of the baselines) on ``samples``, with breakdowns."""
    if len(samples) == 0:
        return {"n": 0, "top1": float("nan"), "top3": float("nan"), "nll": float("nan")}
    logits = model_logits(model, samples, threads=threads)
    y = samples.labels
    h1, h3 = topk_hits(logits, y, 1), topk_hits(logits, y, 3)
    out = {"n": int(len(samples)), "top1": float(h1.mean()), "top3": float(h3.mean()), "nll": _nll(logits, y),
           "mean_options": float(samples.n_candidates.mean() + 1), "none_share": float((y == 0).mean())}
    groups = {"label_spot": y > 0, "label_none": y == 0, "parkers": samples.kind == 0,
              "leavers_wanderers": samples.kind > 0}
    groups.update({f"lot_{LOT_NAMES[c]}": samples.lot == c for c in np.unique(samples.lot)})
    out["by"] = {k: {"n": int(m.sum()), "top1": float(h1[m].mean()), "top3": float(h3[m].mean())}
                 for k, m in groups.items() if m.any()}
    if with_baselines:
        for name, ahead in (("nearest_ahead", True), ("nearest", False)):
            sc = baseline_scores(samples, ahead)
            b1, b3 = topk_hits(sc, y, 1), topk_hits(sc, y, 3)
            out[name] = {"top1": float(b1.mean()), "top3": float(b3.mean()),
                         "by": {k: {"top1": float(b1[m].mean()), "top3": float(b3[m].mean())}
                                for k, m in groups.items() if m.any()}}
    return out


@dataclass
class TrainReport:
    config: dict
    history: list[dict]
    metrics: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return asdict(self)

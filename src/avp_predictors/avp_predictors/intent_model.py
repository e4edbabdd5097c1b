"""Intent model (paper §V-A): the ParkPredict+ "SmallRegularizedCNN" on reconstructed BEVs (§V-B).

For observed dynamic vehicle V_k the network scores every candidate spot i in I_can,k (BEV I_k,i with the
spot marked purple) and one "none / keep exploring" option (the unmarked I_k,0), each with 5 non-spatial
features (reference sheet §1.3, with the paper's definitions of §V-A):

    [cos_k,i, d_k,i, v_hat_k, d_ent, t_lot]

cos_k,i: cosine between V_k's heading and the vector from V_k to the spot centre; d_k,i: distance to the
spot centre (m); v_hat_k: speed from the last two history poses (m/s); d_ent: distance from V_k's *true*
position to the lot entrance (m) — ParkPredict+'s training data fed ground coordinates through a
pixel->ground transform here (sheet §1.3), which is not copied; t_lot: time in the lot in minutes
(ParkPredict+'s unit), counted from the oldest history pose of V_k's first observation. The "none" row is
[0, 0, v_hat, d_ent, t_lot].

Network (sheet §1.4), adapted to the input size: 3 blocks Conv(k=7, 5, 3; 3->8->8->3 channels, no padding)
-> BatchNorm2d -> Dropout(0.2) -> LeakyReLU(0.01) -> MaxPool2d(2); flatten || 5 features -> Linear(100) ->
BatchNorm1d -> Dropout(0.2) -> LeakyReLU(0.01) -> Linear(1): one logit per candidate. A 100 px input gives
3 x 9 x 9 = 243 image features (400 px: 6627 as ParkPredict+). Probabilities (sheet §1.5): sigmoid of each
logit, divided by their sum over the candidates of V_k (not a softmax).

**The head's activation is ours.** ParkPredict+ has it commented out (sheet §1.4), which makes the head affine:
logit_i = a . conv(I_k,i) + c . [cos_k,i, d_k,i] + e . [v_hat_k, d_ent, t_lot] + b. The last three features are
the same for every option of V_k, so their term is the same constant in every logit and cancels from every
comparison: the ranking (top-k ranks the logits) can never depend on the car's speed, its distance to the
entrance or its time in the lot — "slowing down next to a free spot" and "cruising past it" rank alike. With
the LeakyReLU they interact with the per-option inputs (docs/intent_model.md measures the difference).

Inference (all three ``mode``s compute the same logits; tests compare them):

* "reference": the torch module above on every image;
* "fused": :class:`FusedIntentNet` — BatchNorm folded into the layer before it, dropout dropped, LeakyReLU
  moved after the max-pool (it is increasing, so it commutes with max), pooling by strided maxima (this
  CPU build's MaxPool2d kernel is several times slower on these small tensors), and the last 6 of 100
  input rows / cols cropped (floor-mode pooling never reads them);
* "incremental" (default): the images of one vehicle differ only inside the marked spot. conv1 is affine,
  so conv1(I_k,i) = conv1(I_k,0) + conv1_linear(I_k,i - I_k,0), the difference being convolved over the
  marked box only; the rest of the stack (receptive field 30 px, stride 8 px, no padding) is recomputed on
  the patch of conv1's output that feeds the output cells whose 30 px window meets the box, aligned to the
  8 px grid so that the pools line up, and those cells replace I_k,0's. Per candidate this costs a
  fraction of a full pass; I_k,0 is computed once per vehicle.

Untrained (random, seeded) weights work: :meth:`IntentPredictor.predict` then returns valid but
uninformative distributions.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from avp_belief_map.belief import BeliefMap
from avp_belief_map.bev import BEVConfig, BEVRenderer, VehicleBEV
from avp_predictors.intent_features import (  # noqa: F401 - re-exported: the model's API
    FEATURE_NAMES,
    INTENT_MODES,
    MOTION_COLUMN,
    MOTION_FEATURES,
    N_FEATURES,
    PARKPREDICT_FEATURES,
    ROLL_COLUMN,
    ROLL_SPEED,
    SPEED_WINDOWS,
    intent_features,
    motion_features,
)
from avp_predictors.intent_net import (  # noqa: F401 - re-exported: the model's API
    CHANNELS,
    KERNELS,
    SLOPE,
    WEIGHTS_FILE,
    FusedIntentNet,
    SmallRegularizedCNN,
    conv_output_size,
    default_weights_path,
    images_to_tensor,
    load_cnn,
    max_pool_2x2,
    receptive_field,
    sigmoid_normalise,
    weights_path,
)
from avp_predictors.intention import Intention, split_none_mass
from avp_world.lot import LotMap
from avp_world.types import Observation, ObservedVehicle

#: how the model runs on a step's images (its torch-free home is intent_features, for the parameter specs)
MODES = INTENT_MODES


class IntentPredictor:
    """The intent model of §V-A on reconstructed BEVs: ``predict(obs, vehicle, beliefs, lot) -> Intention``.

    Args:
        lot: the lot map (can also be given per call).
        bev_config: BEV reconstruction parameters (image size and resolution set the network input).
        model: a :class:`SmallRegularizedCNN` (e.g. trained); default: seeded random weights.
        seed: seed of the random weights.
        mode: how logits are computed, all the same function: "incremental" (fused network + the shared-
            feature shortcut of the module docstring, fastest), "fused" (:class:`FusedIntentNet` on every
            image) or "reference" (the plain torch module on every image).
    """

    def __init__(self, lot: LotMap | None = None, bev_config: BEVConfig = BEVConfig(),
                 model: SmallRegularizedCNN | None = None, seed: int = 0, mode: str = "incremental"):
        self.bev_config = bev_config.validate()
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        if model is None:
            with torch.random.fork_rng(devices=[]):
                torch.manual_seed(int(seed))
                model = SmallRegularizedCNN(bev_config.size_px)
        if model.image_size != bev_config.size_px:
            raise ValueError(f"model input {model.image_size} px != BEV size {bev_config.size_px} px")
        self.model = model.eval()
        self.net = FusedIntentNet(self.model)
        self.mode = mode
        self.field, self.stride = receptive_field()
        self._renderer: BEVRenderer | None = BEVRenderer(lot, bev_config) if lot is not None else None
        self._first_seen: dict[int, float] = {}
        self._last_t = -math.inf
        self._rolls: dict[int, tuple[float, np.ndarray, float]] = {}  # id -> (t, position, slow_roll_distance)

    # ------------------------------------------------------------------ state
    def renderer(self, lot: LotMap | None = None) -> BEVRenderer:
        if lot is not None and (self._renderer is None or self._renderer.lot is not lot):
            self._renderer = BEVRenderer(lot, self.bev_config)
        if self._renderer is None:
            raise ValueError("no lot: pass one to IntentPredictor(...) or to predict(...)")
        return self._renderer

    def reset(self) -> None:
        """Forget the time-in-lot bookkeeping (new episode)."""
        self._first_seen.clear()
        self._rolls.clear()
        self._last_t = -math.inf

    def time_in_lot(self, obs: Observation, vehicle: ObservedVehicle) -> float:
        """Minutes since the oldest history pose of ``vehicle``'s first observation (episode-local). Also
        updates the vehicle's :meth:`roll_distance` (call it every step for every observed dynamic vehicle)."""
        if obs.t < self._last_t:  # time went back: a new episode
            self.reset()
        self._last_t = obs.t
        span = (len(vehicle.history) - 1) * obs.dt
        first = self._first_seen.setdefault(int(vehicle.id), obs.t - span)
        if self.net.n_features > ROLL_COLUMN:
            self.roll_distance(obs, vehicle)
        return max(0.0, obs.t - first) / 60.0

    def roll_distance(self, obs: Observation, vehicle: ObservedVehicle) -> float:
        """Metres ``vehicle`` has driven since its speed last fell below ROLL_SPEED, as far as the ego has seen
        it (0 while it drives faster): its memory beyond the 4 s history, from its own observations only. On
        first sight it is read from the history (back to the last step at or above ROLL_SPEED); then each new
        observation adds the displacement since the previous one while the vehicle is slow."""
        vid = int(vehicle.id)
        prev = self._rolls.get(vid)
        if prev is not None and prev[0] == obs.t:  # already updated at this step
            return prev[2]
        h = np.asarray(vehicle.history, dtype=float).reshape(-1, 3)
        xy = np.asarray(vehicle.pose, dtype=float)[:2]
        step = np.hypot(*np.diff(h[:, :2], axis=0).T) if len(h) > 1 else np.zeros(0)
        slow_now = (step[-1] / obs.dt < ROLL_SPEED) if len(step) and obs.dt > 0 else False
        if not slow_now:
            roll = 0.0
        elif prev is None:
            fast = np.nonzero(step / obs.dt >= ROLL_SPEED)[0]
            roll = float(step[(fast[-1] + 1) if len(fast) else 0:].sum())
        else:
            roll = prev[2] + float(np.hypot(*(xy - prev[1])))
        self._rolls[vid] = (obs.t, xy.copy(), roll)
        return roll

    @classmethod
    def pretrained(cls, lot: LotMap | None = None, bev_config: BEVConfig = BEVConfig(), mode: str = "incremental",
                   path: str | Path | None = None) -> IntentPredictor:
        """An intent model with trained weights: ``path`` (or a name in models/) or the shipped ones.
        FileNotFoundError names a missing file."""
        p = weights_path(str(path)) if path is not None else default_weights_path()
        if not p.is_file():
            raise FileNotFoundError(f"intent weights {p}: no such file (run `avp train-intent`)")
        pred = cls(lot, bev_config, mode=mode)
        pred.load_weights(p)
        return pred

    def load_weights(self, path: str | Path) -> None:
        """Load a state dict saved with ``torch.save(model.state_dict(), path)`` (:func:`load_cnn`)."""
        self.model = load_cnn(path, self.model.image_size)  # in eval mode
        self.net = FusedIntentNet(self.model)

    # ------------------------------------------------------------------ inference
    def predict(self, obs: Observation, vehicle: ObservedVehicle, beliefs: np.ndarray | BeliefMap,
                lot: LotMap | None = None, *, ego_history: np.ndarray | None = None) -> Intention:
        """Intention of one observed dynamic vehicle (§V-A) from the belief b~ after eq. (7)."""
        return self.predict_all(obs, [vehicle], beliefs, lot, ego_history=ego_history)[0]

    def predict_all(self, obs: Observation, vehicles: Sequence[ObservedVehicle], beliefs: np.ndarray | BeliefMap,
                    lot: LotMap | None = None, *, ego_history: np.ndarray | None = None,
                    return_bevs: bool = False) -> list[Intention] | tuple[list[Intention], list[VehicleBEV]]:
        """Intentions of several vehicles with one network call over all their candidates.

        ``beliefs`` is b~_t (array in lot spot order) or a :class:`BeliefMap` after ``observe`` (its
        ``b_tilde`` and observed spots are used).
        """
        bevs, feats = self.inputs(obs, vehicles, beliefs, lot, ego_history=ego_history)
        logits = self.logits(bevs, feats)
        out = []
        start = 0
        for bev, f in zip(bevs, feats, strict=True):
            p = sigmoid_normalise(logits[start:start + len(f)])
            start += len(f)
            p_none = float(p[0])
            ex = split_none_mass(p_none, len(bev.exploration_points))
            out.append(Intention(
                vehicle_id=bev.vehicle_id,
                spot_ids=bev.candidate_spot_ids.copy(),
                spot_probabilities=p[1:].astype(float),
                exploration_points=bev.exploration_points[: len(ex)].copy(),
                exploration_probabilities=ex,
                none_probability=p_none,
            ))
        return (out, bevs) if return_bevs else out

    def inputs(self, obs: Observation, vehicles: Sequence[ObservedVehicle], beliefs: np.ndarray | BeliefMap,
               lot: LotMap | None = None, *, ego_history: np.ndarray | None = None
               ) -> tuple[list[VehicleBEV], list[np.ndarray]]:
        """The network inputs of :meth:`predict_all`: per vehicle its BEV (I_k,0 and the marked I_k,i, §V-B)
        and its (K + 1, N_FEATURES) features (§V-A) — the columns past the network's ``n_features`` are left at
        their no-history defaults (not computed). The training data (:mod:`avp_training`) is made with
        this same call on an all-features network."""
        r = self.renderer(lot)
        if isinstance(beliefs, BeliefMap):
            b_tilde, observed = beliefs.b_tilde, beliefs.observed_mask
        else:
            b_tilde, observed = np.asarray(beliefs, dtype=float), r.observed_mask(obs)
        bevs = r.render_all(obs, list(vehicles), b_tilde, observed, ego_history)
        # columns the network does not read are not computed (left at their no-history defaults)
        n = self.net.n_features
        feats = [intent_features(bev.pose, bev.speed, r.spot_centers[bev.candidate_idx], r.lot.entrance,
                                 self.time_in_lot(obs, v), v.history if n > MOTION_COLUMN else None, obs.dt,
                                 self.roll_distance(obs, v) if n > ROLL_COLUMN else 0.0)
                 for bev, v in zip(bevs, vehicles, strict=True)]
        return bevs, feats

    @torch.inference_mode()
    def logits(self, bevs: Sequence[VehicleBEV], features: Sequence[np.ndarray]) -> np.ndarray:
        """Concatenated logits, per vehicle [none, candidate 1..K] (the order of ``VehicleBEV.images()``)."""
        if not bevs:
            return np.zeros(0)
        f = torch.from_numpy(np.concatenate(features).astype(np.float32))
        if self.mode == "incremental":
            return self.net.head(self._encode_incremental(bevs), f).numpy().astype(float)
        x = images_to_tensor(np.concatenate([b.images() for b in bevs]))
        net = self.net if self.mode == "fused" else self.model
        return net(x, f).numpy().astype(float)

    def _encode_incremental(self, bevs: Sequence[VehicleBEV]) -> torch.Tensor:
        """Conv features of [I_k,0, I_k,1..K] for every vehicle, recomputing only what a marking can change.

        conv1 is affine, so conv1(I_k,i) = conv1(I_k,0) + conv1_linear(I_k,i - I_k,0), and the difference is
        zero outside the marked spot's box: it is convolved over that box only. The rest of the stack is
        recomputed on a patch of conv1's output that covers every output cell whose receptive field meets
        the box (patches aligned to the 8 px grid so the pools line up), and those cells replace I_k,0's.
        The bookkeeping runs on numpy views of the (channels-last) tensors.
        """
        net, field, stride = self.net, self.field, self.stride
        n_out = net.out_size
        m = net.kernel1 - 1  # conv1 shrinks by 6 px
        u = net.used  # the output only depends on the first 94 of 100 rows / cols
        a1 = net.conv1(images_to_tensor(np.stack([b.image[:u, :u] for b in bevs])))  # (V, 8, u - 6, u - 6)
        base = net.after_conv1(a1).numpy()  # (V, 3, n, n)
        counts = np.array([1 + len(b.candidate_boxes) for b in bevs])
        full = np.repeat(base, counts, axis=0)
        boxes = np.concatenate([b.candidate_boxes for b in bevs]).reshape(-1, 4).astype(np.int64)
        veh = np.repeat(np.arange(len(bevs)), counts - 1)
        cand = np.concatenate([np.arange(c - 1) for c in counts])
        rows = np.concatenate([[0], np.cumsum(counts)[:-1]])[veh] + 1 + cand  # row of each candidate in ``full``

        def cells(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            # output cells i whose input window [stride i, stride i + field - 1] meets pixels lo..hi
            return np.maximum(0, -((field - 1 - lo) // stride)), np.minimum(n_out - 1, hi // stride)

        ra, rb = cells(boxes[:, 0], boxes[:, 1])
        ca, cb = cells(boxes[:, 2], boxes[:, 3])
        # I_k,0's features stay where the image is unchanged or marked only in rows / cols no output reads
        keep = (boxes[:, 1] >= boxes[:, 0]) & (ra <= rb) & (ca <= cb)
        if not keep.any():
            return torch.from_numpy(full)
        boxes, veh, cand, rows = boxes[keep], veh[keep], cand[keep], rows[keep]
        ra, rb, ca, cb = ra[keep], rb[keep], ca[keep], cb[keep]
        nr, nc = int((rb - ra).max()) + 1, int((cb - ca).max()) + 1  # one patch size for the whole batch
        py, px = np.minimum(ra, n_out - nr) * stride, np.minimum(ca, n_out - nc) * stride
        hr, hc = stride * (nr - 1) + field - m, stride * (nc - 1) + field - m  # conv1-output patch size
        bh = int((boxes[:, 1] - boxes[:, 0]).max()) + 1 + 2 * m  # difference window (input pixels)
        bw = int((boxes[:, 3] - boxes[:, 2]).max()) + 1 + 2 * m
        y0, x0 = boxes[:, 0] - m, boxes[:, 2] - m  # window origins (may stick out of the image)
        size = bevs[0].image.shape[0]
        diffs = np.zeros((len(boxes), bh, bw, 3), dtype=np.float32)
        for p in range(len(boxes)):
            ya, yb, xa, xb = max(y0[p], 0), min(y0[p] + bh, size), max(x0[p], 0), min(x0[p] + bw, size)
            img, mk = bevs[veh[p]].image, bevs[veh[p]].candidate_images[cand[p]]
            diffs[p, ya - y0[p]: yb - y0[p], xa - x0[p]: xb - x0[p]] = (
                mk[ya:yb, xa:xb].astype(np.float32) - img[ya:yb, xa:xb])
        # conv1 of the differences: rows y0 .. y0 + dh - 1, cols x0 .. of conv1's output
        delta = net.conv1_linear(images_to_tensor(diffs)).permute(0, 2, 3, 1).numpy()  # (P, dh, dw, 8)
        dh, dw = delta.shape[1], delta.shape[2]
        a1_np = a1.permute(0, 2, 3, 1).numpy()  # (V, h1, w1, 8) view
        patches = np.empty((len(boxes), hr, hc, a1_np.shape[3]), dtype=np.float32)
        for p in range(len(boxes)):
            patches[p] = a1_np[veh[p], py[p]: py[p] + hr, px[p]: px[p] + hc]
            ya, yb = max(y0[p], py[p]), min(y0[p] + dh, py[p] + hr)
            xa, xb = max(x0[p], px[p]), min(x0[p] + dw, px[p] + hc)
            if ya < yb and xa < xb:
                patches[p, ya - py[p]: yb - py[p], xa - px[p]: xb - px[p]] += (
                    delta[p, ya - y0[p]: yb - y0[p], xa - x0[p]: xb - x0[p]])
        sub = net.after_conv1(torch.from_numpy(patches).permute(0, 3, 1, 2)).numpy()  # (P, 3, nr, nc)
        ar, ac = py // stride, px // stride
        for p in range(len(boxes)):
            full[rows[p], :, ar[p]: ar[p] + nr, ac[p]: ac[p] + nc] = sub[p]
        return torch.from_numpy(full)

"""The intent CNN of §V-A (ROS-free): ParkPredict+'s SmallRegularizedCNN (:class:`SmallRegularizedCNN`, see the
"Network" part of :mod:`.intent_model`), its inference form :class:`FusedIntentNet` (BatchNorm folded, dropout
dropped, pooling before the activation: the same function, fewer operations) and its weight files.
:class:`~avp_predictors.intent_model.IntentPredictor` runs them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn

from avp_predictors.intent_features import N_FEATURES
from avp_predictors.weights import resolve_weights

KERNELS = (7, 5, 3)
CHANNELS = (3, 8, 8, 3)


def conv_output_size(size: int) -> int:
    """Side of the conv-stack output for a ``size`` px input (valid convs, floor-mode 2x2 pools)."""
    n = int(size)
    for k in KERNELS:
        n = (n - k + 1) // 2
    if n < 1:
        raise ValueError(f"input of {size} px is too small for the conv stack")
    return n


def receptive_field() -> tuple[int, int]:
    """(receptive field, stride) in input pixels of one output cell of the conv stack: (30, 8)."""
    r, s = 1, 1
    for k in KERNELS:
        r += (k - 1) * s  # conv
        r += s  # 2x2 pool
        s *= 2
    return r, s


def _block(c_in: int, c_out: int, k: int, dropout: float) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(c_in, c_out, k), nn.BatchNorm2d(c_out), nn.Dropout(dropout),
                         nn.LeakyReLU(SLOPE), nn.MaxPool2d(2))


SLOPE = 0.01  # LeakyReLU slope of the conv blocks and the head


class SmallRegularizedCNN(nn.Module):
    """ParkPredict+ SmallRegularizedCNN (sheet §1.4) for ``image_size`` px RGB inputs in [0, 1]."""

    def __init__(self, image_size: int = 100, n_features: int = N_FEATURES, hidden: int = 100,
                 dropout: float = 0.2):
        super().__init__()
        if not 1 <= int(n_features) <= N_FEATURES:
            raise ValueError(f"n_features must be 1..{N_FEATURES} (the first n of FEATURE_NAMES), got {n_features}")
        self.image_size = int(image_size)
        self.n_features = int(n_features)  # the first n of FEATURE_NAMES (5: ParkPredict+'s)
        self.out_size = conv_output_size(self.image_size)
        self.conv = nn.Sequential(*[_block(CHANNELS[i], CHANNELS[i + 1], KERNELS[i], dropout) for i in range(3)])
        n_flat = CHANNELS[-1] * self.out_size**2
        self.fc = nn.Sequential(nn.Linear(n_flat + n_features, hidden), nn.BatchNorm1d(hidden), nn.Dropout(dropout),
                                nn.LeakyReLU(SLOPE), nn.Linear(hidden, 1))  # the activation: module docstring

    def encode(self, images: torch.Tensor) -> torch.Tensor:
        """(B, 3, H, W) -> (B, 3, h, w) conv features."""
        return self.conv(images)

    def head(self, encoded: torch.Tensor, features: torch.Tensor) -> torch.Tensor:
        """(B, 3, h, w) conv features and (B, >= n_features) features -> (B,) logits (the first ``n_features``
        columns are used: the feature rows are always all of FEATURE_NAMES)."""
        return self.fc(torch.cat([encoded.flatten(1), features[:, : self.n_features]], dim=1)).squeeze(1)

    def forward(self, images: torch.Tensor, features: torch.Tensor) -> torch.Tensor:
        return self.head(self.encode(images), features)


def sigmoid_normalise(logits: np.ndarray | torch.Tensor) -> np.ndarray:
    """ParkPredict+ probabilities (sheet §1.5): sigmoid(z_j) / sum_j sigmoid(z_j) (float64; numpy, no overflow)."""
    z = logits.detach().cpu().numpy() if isinstance(logits, torch.Tensor) else logits
    z = np.asarray(z, dtype=np.float64)
    e = np.exp(-np.abs(z))
    s = np.where(z >= 0.0, 1.0 / (1.0 + e), e / (1.0 + e))
    return s / s.sum()


def images_to_tensor(images: np.ndarray) -> torch.Tensor:
    """(B, H, W, 3) uint8 -> (B, 3, H, W) float32 in [0, 1] (channels-last memory, no transpose copy)."""
    return torch.from_numpy(np.ascontiguousarray(images)).permute(0, 3, 1, 2).float().mul_(1.0 / 255.0)


def load_cnn(path: str | Path, image_size: int = 100) -> SmallRegularizedCNN:
    """A :class:`SmallRegularizedCNN` with the state dict at ``path`` (saved by ``torch.save(model.state_dict())``),
    in eval mode. The number of features it takes (the first n of FEATURE_NAMES; 5 = ParkPredict+'s) is read from
    its first linear layer. ValueError names the file when it is not such a state dict."""
    state = torch.load(Path(path), map_location="cpu", weights_only=True)
    try:
        n = int(state["fc.0.weight"].shape[1]) - CHANNELS[-1] * conv_output_size(image_size) ** 2
        model = SmallRegularizedCNN(image_size, n_features=n)
        model.load_state_dict(state)
    except (KeyError, ValueError, RuntimeError, AttributeError) as e:
        raise ValueError(f"intent weights {path}: not a {image_size} px SmallRegularizedCNN state dict ({e})") from None
    return model.eval()


WEIGHTS_FILE = "intent_cnn.pt"  # the shipped state dict, under avp_predictors/models/ (docs/intent_model.md)


def default_weights_path() -> Path:
    """Where the shipped intent CNN weights live: ``avp_predictors/models/intent_cnn.pt`` (made by
    ``avp train-intent``; a JSON card with the same stem records data, command and accuracy)."""
    return Path(__file__).resolve().parent / "models" / WEIGHTS_FILE


def weights_path(weights: str = "") -> Path:
    """The file ``weights`` names: a path, or the name of a file in the package's models/ (e.g.
    ``intent_cnn_tracked.pt``); empty: the shipped file (:func:`default_weights_path`)."""
    return resolve_weights(weights, default_weights_path())


def _cell_range(lo: int, hi: int, n_out: int, field: int, stride: int) -> tuple[int, int]:
    """Output cells whose window [stride*i, stride*i + field - 1] meets pixels lo..hi (inclusive)."""
    a = max(0, -((field - 1 - lo) // stride))  # ceil((lo - field + 1) / stride)
    b = min(n_out - 1, hi // stride)
    return a, b


def max_pool_2x2(x: torch.Tensor) -> torch.Tensor:
    """nn.MaxPool2d(2) (floor mode) as the max of four strided views: the same numbers, several times faster
    than this CPU build's pooling kernel on these small tensors."""
    h, w = x.shape[-2] // 2 * 2, x.shape[-1] // 2 * 2
    return torch.maximum(torch.maximum(x[..., 0:h:2, 0:w:2], x[..., 1:h:2, 0:w:2]),
                         torch.maximum(x[..., 0:h:2, 1:w:2], x[..., 1:h:2, 1:w:2]))


class FusedIntentNet:
    """Inference form of a :class:`SmallRegularizedCNN` in eval mode (same function, fewer operations).

    Each BatchNorm is folded into the layer before it, dropout is the identity, and LeakyReLU is applied
    after the 2x2 max-pool (it is strictly increasing, so it commutes with max): per block
    y = leaky_relu(maxpool(conv'(x))). Build it again after the model's weights change.
    """

    def __init__(self, model: SmallRegularizedCNN):
        model = model.eval()
        self.out_size = model.out_size
        self.n_features = model.n_features
        self.slope = SLOPE
        self.convs: list[tuple[torch.Tensor, torch.Tensor]] = []
        with torch.no_grad():
            for block in model.conv:
                conv, bn = block[0], block[1]
                scale = bn.weight / torch.sqrt(bn.running_var + bn.eps)
                w = (conv.weight * scale[:, None, None, None]).contiguous(memory_format=torch.channels_last)
                b = (conv.bias - bn.running_mean) * scale + bn.bias
                self.convs.append((w.detach().clone(), b.detach().clone()))
            fc1, bn1, fc2 = model.fc[0], model.fc[1], model.fc[4]
            scale = bn1.weight / torch.sqrt(bn1.running_var + bn1.eps)
            self.w1 = (fc1.weight * scale[:, None]).detach().clone()
            self.b1 = ((fc1.bias - bn1.running_mean) * scale + bn1.bias).detach().clone()
            self.w2 = fc2.weight.detach().clone()
            self.b2 = fc2.bias.detach().clone()
        self.kernel1 = int(self.convs[0][0].shape[-1])
        field, stride = receptive_field()
        self.used = stride * (self.out_size - 1) + field  # input rows/cols the output depends on (94 of 100)

    def conv1(self, x: torch.Tensor) -> torch.Tensor:
        """First conv with BN folded in (affine in x): (B, 3, H, W) -> (B, 8, H - 6, W - 6)."""
        w, b = self.convs[0]
        return torch.nn.functional.conv2d(x, w, b)

    def conv1_linear(self, dx: torch.Tensor) -> torch.Tensor:
        """The linear part of :meth:`conv1` (no bias), for image differences."""
        return torch.nn.functional.conv2d(dx, self.convs[0][0])

    def after_conv1(self, a1: torch.Tensor) -> torch.Tensor:
        """Everything after conv1: (B, 8, h1, w1) -> (B, 3, h, w)."""
        lrelu = torch.nn.functional.leaky_relu
        y = lrelu(max_pool_2x2(a1), self.slope)
        for w, b in self.convs[1:]:
            y = lrelu(max_pool_2x2(torch.nn.functional.conv2d(y, w, b)), self.slope)
        return y

    def encode(self, x: torch.Tensor) -> torch.Tensor:
        """The floor-mode pools never read the last rows/cols: they are cropped first (same output)."""
        return self.after_conv1(self.conv1(x[..., : self.used, : self.used]))

    def head(self, encoded: torch.Tensor, features: torch.Tensor) -> torch.Tensor:
        x = torch.cat([encoded.flatten(1), features[:, : self.n_features]], dim=1)
        h = torch.nn.functional.linear(x, self.w1, self.b1)
        h = torch.nn.functional.leaky_relu(h, self.slope)
        return torch.nn.functional.linear(h, self.w2, self.b2).squeeze(1)

    def __call__(self, images: torch.Tensor, features: torch.Tensor) -> torch.Tensor:
        return self.head(self.encode(images), features)

"""The trajectory transformer of the learned predictor (ParkPredict+, reference sheet §2.2; paper §VI-B-1), its
architecture settings and its weight files. :mod:`.learned_prediction` explains the inputs and the network
(its "Network" paragraph) and runs it as a §V-C predictor; :mod:`avp_trajectory_training.train` trains it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from avp_predictors.intent_model import CHANNELS, KERNELS, SLOPE, SmallRegularizedCNN, conv_output_size
from avp_predictors.weights import resolve_weights

MODEL_DT = 0.4  # s between model poses (ParkPredict+'s stride, sheet §2.1)
N_HIST = 10  # history poses t - 3.6 s ... t
N_FUT = 10  # future poses t + 0.4 s ... t + 4.0 s
POS_SCALE = 10.0  # m: positions are divided by this inside the network
VEL_SCALE = 5.0  # pose increments (per 0.4 s) are multiplied by this on top
WEIGHTS_FILE = "trajectory_transformer.pt"


@dataclass(frozen=True)
class TransformerConfig:
    """Architecture (sheet §2.2 sized for a CPU; the card records the values of the shipped weights)."""

    image_size: int = 100
    d_model: int = 64
    n_heads: int = 4
    enc_layers: int = 2
    dec_layers: int = 2
    d_ff: int = 128
    d_intent: int = 128  # IntentFF hidden width (ParkPredict+: 128)
    dropout: float = 0.1


# ----------------------------------------------------------------------------------------- network


def sinusoidal_encoding(n: int, d: int) -> torch.Tensor:
    """(n, d) sinusoidal encoding of positions 0..n-1 (Vaswani et al.); added per time step to (B, n, d)."""
    pos = torch.arange(n, dtype=torch.float32)[:, None]
    div = torch.exp(torch.arange(0, d, 2, dtype=torch.float32) * (-math.log(10000.0) / d))
    pe = torch.zeros(n, d)
    pe[:, 0::2] = torch.sin(pos * div)
    pe[:, 1::2] = torch.cos(pos * div)
    return pe


class Attention(nn.Module):
    """Multi-head attention on batch-first tensors (scaled dot product)."""

    def __init__(self, d: int, heads: int):
        super().__init__()
        self.heads = heads
        self.q = nn.Linear(d, d)
        self.kv = nn.Linear(d, 2 * d)
        self.out = nn.Linear(d, d)

    def keys(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        b, n, d = x.shape
        k, v = self.kv(x).view(b, n, 2, self.heads, d // self.heads).permute(2, 0, 3, 1, 4)
        return k, v

    def forward(self, x: torch.Tensor, kv: tuple[torch.Tensor, torch.Tensor], causal: bool = False,
                dropout: float = 0.0) -> torch.Tensor:
        b, n, d = x.shape
        q = self.q(x).view(b, n, self.heads, d // self.heads).transpose(1, 2)
        y = F.scaled_dot_product_attention(q, kv[0], kv[1], dropout_p=dropout, is_causal=causal)
        return self.out(y.transpose(1, 2).reshape(b, n, d))


class EncoderLayer(nn.Module):
    def __init__(self, c: TransformerConfig):
        super().__init__()
        self.attn = Attention(c.d_model, c.n_heads)
        self.ff = nn.Sequential(nn.Linear(c.d_model, c.d_ff), nn.GELU(), nn.Linear(c.d_ff, c.d_model))
        self.n1, self.n2 = nn.LayerNorm(c.d_model), nn.LayerNorm(c.d_model)
        self.drop = nn.Dropout(c.dropout)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.n1(x + self.drop(self.attn(x, self.attn.keys(x))))
        return self.n2(x + self.drop(self.ff(x)))


class DecoderLayer(nn.Module):
    """Masked self-attention -> cross-attention to the memory -> cross-attention to the intent -> FF (post-norm)."""

    def __init__(self, c: TransformerConfig):
        super().__init__()
        self.self_attn = Attention(c.d_model, c.n_heads)
        self.mem_attn = Attention(c.d_model, c.n_heads)
        self.int_attn = Attention(c.d_model, c.n_heads)
        self.ff = nn.Sequential(nn.Linear(c.d_model, c.d_ff), nn.GELU(), nn.Linear(c.d_ff, c.d_model))
        self.norms = nn.ModuleList([nn.LayerNorm(c.d_model) for _ in range(4)])
        self.drop = nn.Dropout(c.dropout)

    def forward(self, x: torch.Tensor, mem_kv, int_kv) -> torch.Tensor:
        n = self.norms
        x = n[0](x + self.drop(self.self_attn(x, self.self_attn.keys(x), causal=True)))
        x = n[1](x + self.drop(self.mem_attn(x, mem_kv)))
        x = n[2](x + self.drop(self.int_attn(x, int_kv)))
        return n[3](x + self.drop(self.ff(x)))


class TrajectoryTransformer(nn.Module):
    """ParkPredict+'s TrajectoryPredictorWithDecoderIntentCrossAttention (sheet §2.2), see the module docstring.

    Shapes: images (B, 3, H, W) in [0, 1]; history (B, N_HIST, 3) and poses (B, T, 3) in the agent frame
    (metres, radians); goal (B, 2) agent frame (metres).
    """

    def __init__(self, config: TransformerConfig = TransformerConfig()):
        super().__init__()
        c = self.config = config
        self.conv = nn.Sequential(*[nn.Sequential(nn.Conv2d(CHANNELS[i], CHANNELS[i + 1], KERNELS[i]),
                                                  nn.BatchNorm2d(CHANNELS[i + 1]), nn.LeakyReLU(SLOPE),
                                                  nn.MaxPool2d(2)) for i in range(3)])
        n_img = CHANNELS[-1] * conv_output_size(c.image_size) ** 2
        self.enc_in = nn.Linear(3 + n_img, c.d_model)
        self.dec_in = nn.Linear(6, c.d_model)
        self.intent = nn.Sequential(nn.Linear(2, c.d_intent), nn.ReLU(), nn.LayerNorm(c.d_intent),
                                    nn.Dropout(c.dropout), nn.Linear(c.d_intent, c.d_model), nn.LayerNorm(c.d_model),
                                    nn.Dropout(c.dropout))
        self.encoder = nn.ModuleList([EncoderLayer(c) for _ in range(c.enc_layers)])
        self.decoder = nn.ModuleList([DecoderLayer(c) for _ in range(c.dec_layers)])
        self.head = nn.Linear(c.d_model, 3)
        self.register_buffer("pe", sinusoidal_encoding(N_HIST + N_FUT + 1, c.d_model), persistent=False)
        self.register_buffer("scale", torch.tensor([1.0 / POS_SCALE, 1.0 / POS_SCALE, 1.0]), persistent=False)

    def init_conv_from_intent(self, intent: SmallRegularizedCNN) -> None:
        """Copy the intent CNN's conv blocks (conv + BatchNorm) into this encoder (sheet §2.2)."""
        for mine, theirs in zip(self.conv, intent.conv, strict=True):
            mine[0].load_state_dict(theirs[0].state_dict())
            mine[1].load_state_dict(theirs[1].state_dict())

    def conv_front(self, images: torch.Tensor) -> torch.Tensor:
        """Conv blocks 1-2 (kept at the intent CNN's weights in training): (B, 3, H, W) -> (B, 8, h2, w2)."""
        return self.conv[1](self.conv[0](images))

    def encode(self, images: torch.Tensor, history: torch.Tensor) -> torch.Tensor:
        """(B, N_HIST, d_model) encoder memory."""
        return self.encode_front(self.conv_front(images), history)

    def encode_front(self, front: torch.Tensor, history: torch.Tensor) -> torch.Tensor:
        """:meth:`encode` from the output of :meth:`conv_front`."""
        feat = self.conv[2](front).flatten(1)
        x = torch.cat([history * self.scale, feat[:, None].expand(-1, history.shape[1], -1)], dim=2)
        x = self.enc_in(x) + self.pe[: history.shape[1]]
        for layer in self.encoder:
            x = layer(x)
        return x

    def intent_tokens(self, goal: torch.Tensor) -> torch.Tensor:
        """(B, 2, d_model): [IntentFF(goal), 0] (ParkPredict+'s key/value sequence)."""
        tok = self.intent(goal / POS_SCALE)
        return torch.stack([tok, torch.zeros_like(tok)], dim=1)

    def cross_keys(self, memory: torch.Tensor, intent: torch.Tensor) -> list[tuple]:
        """Per decoder layer the keys / values of the memory and of the intent tokens (computed once per rollout)."""
        return [(layer.mem_attn.keys(memory), layer.int_attn.keys(intent)) for layer in self.decoder]

    def decode(self, inputs: torch.Tensor, prev0: torch.Tensor, memory: torch.Tensor, intent: torch.Tensor,
               keys: list[tuple] | None = None) -> torch.Tensor:
        """Decoder inputs (B, T, 3) (the pose before each predicted one; ``prev0`` (B, 3) the pose before the
        first, i.e. the history pose at t - 0.4 s) -> predicted poses (B, T, 3): each input pose plus its last
        increment (constant velocity and turn rate) plus the network's correction."""
        keys = keys if keys is not None else self.cross_keys(memory, intent)
        step = inputs - torch.cat([prev0[:, None], inputs[:, :-1]], dim=1)
        x = self.dec_in(torch.cat([inputs * self.scale, step * (VEL_SCALE * self.scale)], dim=2))
        x = x + self.pe[N_HIST: N_HIST + inputs.shape[1]]
        for layer, (mem_kv, int_kv) in zip(self.decoder, keys, strict=True):
            x = layer(x, mem_kv, int_kv)
        return inputs + step + self.head(x)

    def forward(self, front: torch.Tensor, history: torch.Tensor, goal: torch.Tensor,
                future: torch.Tensor) -> torch.Tensor:
        """Teacher forcing from :meth:`conv_front` features: decoder inputs [current pose (0, 0, 0), future[:-1]]
        -> predicted future (B, T, 3)."""
        memory = self.encode_front(front, history)
        inputs = torch.cat([torch.zeros_like(future[:, :1]), future[:, :-1]], dim=1)
        return self.decode(inputs, history[:, -2], memory, self.intent_tokens(goal))

    @torch.inference_mode()
    def rollout(self, memory: torch.Tensor, goal: torch.Tensor, prev0: torch.Tensor, n: int = N_FUT) -> torch.Tensor:
        """Autoregressive decoding of ``n`` poses (B, n, 3) from memories (B, N_HIST, d), goals (B, 2) and the
        history poses at t - 0.4 s (B, 3)."""
        return self.free_run(memory, goal, prev0, n)

    def free_run(self, memory: torch.Tensor, goal: torch.Tensor, prev0: torch.Tensor, n: int = N_FUT) -> torch.Tensor:
        """:meth:`rollout` with gradients (the free-running training loss)."""
        intent = self.intent_tokens(goal)
        keys = self.cross_keys(memory, intent)
        seq = torch.zeros(memory.shape[0], 1, 3)
        for _ in range(n):
            out = self.decode(seq, prev0, memory, intent, keys)
            seq = torch.cat([seq, out[:, -1:]], dim=1)
        return seq[:, 1:]


# ----------------------------------------------------------------------------------------- weights


def default_weights_path() -> Path:
    """``avp_predictors/models/trajectory_transformer.pt`` (made by ``avp train-trajectory``; card beside it)."""
    return Path(__file__).resolve().parent / "models" / WEIGHTS_FILE


def save_model(model: TrajectoryTransformer, path: str | Path) -> None:
    """State dict + architecture in one file."""
    from dataclasses import asdict

    torch.save({"config": asdict(model.config), "state_dict": model.state_dict()}, Path(path))


def load_model(path: str | Path) -> TrajectoryTransformer:
    """A model saved by :func:`save_model`; ValueError names a file that cannot be loaded."""
    p = Path(path)
    try:
        blob = torch.load(p, map_location="cpu", weights_only=True)
        model = TrajectoryTransformer(TransformerConfig(**blob["config"]))
        model.load_state_dict(blob["state_dict"])
    except Exception as exc:  # noqa: BLE001 - any unreadable / mismatched file is one clear error
        raise ValueError(f"trajectory weights {p}: cannot load ({exc})") from None
    return model.eval()


def weights_path(weights: str = "") -> Path:
    """The file ``weights`` names: a path, or the name of a file in the package's models/ (e.g.
    ``trajectory_transformer_tracked.pt``); empty: the shipped file (:func:`default_weights_path`)."""
    return resolve_weights(weights, default_weights_path())


def make_model(weights: str = "", seed: int = 0) -> tuple[TrajectoryTransformer, str]:
    """The model and a line saying which weights: the file ``weights`` names (:func:`weights_path`), else the shipped
    file if present, else seeded random weights (valid but uninformative output)."""
    p = weights_path(weights)
    if weights and not p.is_file():
        raise ValueError(f"trajectory weights {p}: no such file")
    if p.is_file():
        return load_model(p), f"trajectory transformer: weights from {p}" + ("" if weights else " (shipped)")
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(seed))
        model = TrajectoryTransformer().eval()
    return model, f"trajectory transformer: untrained seeded random weights (seed {seed}); no shipped weights found"

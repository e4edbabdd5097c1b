"""Which file a model's ``weights`` setting names: one rule for the intent CNN and the trajectory transformer."""

from __future__ import annotations

from pathlib import Path


def resolve_weights(weights: str, default: Path) -> Path:
    """The file ``weights`` names: a path, or the name of a file in the package's models/ (the folder of
    ``default``, e.g. ``intent_cnn_tracked.pt``); empty: ``default``, the shipped file."""
    p = Path(weights) if weights else default
    in_models = default.parent / weights
    return in_models if weights and not p.is_file() and in_models.is_file() else p

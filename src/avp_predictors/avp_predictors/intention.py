"""Intention of one observed dynamic vehicle (paper §V-A): eta_k,i over candidate spots, eta_hat_k,q over
exploration points.

The intent CNN scores every candidate spot plus one "none / keep exploring" option (ParkPredict+); the
mass of that option is spread over the best exploration points as ParkPredict+'s ``expand_distribution``
does (weights linspace(0.9, 0.1, n) over the top n = min(3, #points), normalised; reference sheet §1.6).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

TOP_EXPLORATION_POINTS = 3  # ParkPredict+ keeps the top 3 lanes (sheet §1.6)


@dataclass(frozen=True)
class Intention:
    """Intention probabilities of observed dynamic vehicle V_k at one step (§V-A).

    ``spot_probabilities.sum() + none_probability == 1``; when exploration points exist,
    ``exploration_probabilities.sum() == none_probability`` (the "none" mass split over them),
    otherwise the "none" mass has no goal (``exploration_points`` is empty).
    """

    vehicle_id: int
    spot_ids: np.ndarray  # I_can,k (int64, lot spot ids)
    spot_probabilities: np.ndarray  # eta_k,i, aligned with spot_ids
    exploration_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # s_exp,k,q (x, y, theta)
    exploration_probabilities: np.ndarray = field(default_factory=lambda: np.zeros(0))  # eta_hat_k,q
    none_probability: float = 0.0  # mass of the "none / explore" option

    def spot_probability(self, spot_id: int) -> float:
        """eta_k,i of ``spot_id`` (0 if it is not a candidate)."""
        hit = np.nonzero(self.spot_ids == int(spot_id))[0]
        return float(self.spot_probabilities[hit[0]]) if len(hit) else 0.0


def split_none_mass(none_probability: float, n_points: int, top: int = TOP_EXPLORATION_POINTS) -> np.ndarray:
    """ParkPredict+ ``expand_distribution``: the "none" mass over the first min(top, n) ranked points.

    Weights linspace(0.9, 0.1, n) normalised (n = 3 gives 0.6, 0.333, 0.067). Returns (min(top, n_points),).
    """
    n = min(int(top), int(n_points))
    if n <= 0:
        return np.zeros(0)
    return float(none_probability) * _split_weights(n)


@functools.cache
def _split_weights(n: int) -> np.ndarray:
    w = np.linspace(0.9, 0.1, n)
    w = w / w.sum()
    w.setflags(write=False)
    return w

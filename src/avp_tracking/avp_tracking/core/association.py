"""Gated global-nearest-neighbour association (docs/perception.md, "Tracking").

The cost of pairing track i with detection j is the squared Mahalanobis distance of their positions under the
innovation covariance S = P_xy + R_xy; a pair is allowed only when that distance is below the gate (a chi-square
quantile of 2 degrees of freedom, 11.62 = 99.7 % as Autoware's multi_object_tracker) and their centres are closer
than ``max_distance``. The pairing of least total cost is solved exactly by scipy's ``linear_sum_assignment``
(rectangular matrices; the gated-out pairs priced out of reach and dropped afterwards).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

_OUT = 1e9  # the cost of a gated-out pair


def mahalanobis_costs(track_xy: np.ndarray, track_cov: np.ndarray, det_xy: np.ndarray, det_cov: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """(squared Mahalanobis distances, Euclidean distances), each (n_tracks, n_dets), of the tracks' positions
    ``track_xy`` (T, 2) with covariances ``track_cov`` (T, 2, 2) to the detections ``det_xy`` (D, 2) with
    ``det_cov`` (D, 2, 2)."""
    d = det_xy[None, :, :] - track_xy[:, None, :]  # (T, D, 2)
    S = track_cov[:, None, :, :] + det_cov[None, :, :, :]  # (T, D, 2, 2)
    a, b, c = S[..., 0, 0], S[..., 0, 1], S[..., 1, 1]
    det = np.maximum(a * c - b * b, 1e-12)
    dx, dy = d[..., 0], d[..., 1]
    m2 = (c * dx * dx - 2.0 * b * dx * dy + a * dy * dy) / det
    return m2, np.hypot(dx, dy)


def assign(costs: np.ndarray, allowed: np.ndarray) -> list[tuple[int, int]]:
    """The (track, detection) pairs of least total cost among the ``allowed`` ones (GNN)."""
    if costs.size == 0 or not allowed.any():
        return []
    priced = np.where(allowed, costs, _OUT)
    rows, cols = linear_sum_assignment(priced)
    return [(int(r), int(c)) for r, c in zip(rows, cols, strict=True) if allowed[r, c]]


def gated_pairs(track_xy: np.ndarray, track_cov: np.ndarray, det_xy: np.ndarray, det_cov: np.ndarray,
                gate: float, max_distance: float) -> list[tuple[int, int]]:
    """:func:`assign` of the tracks to the detections under the Mahalanobis ``gate`` and ``max_distance``."""
    if not len(track_xy) or not len(det_xy):
        return []
    m2, dist = mahalanobis_costs(track_xy, track_cov, det_xy, det_cov)
    return assign(m2, (m2 < gate) & (dist < max_distance))

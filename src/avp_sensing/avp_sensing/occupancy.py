"""Which spots are occupied and which vehicles are static (paper §III-A), once or step after step.

A spot S_i is occupied iff some vehicle lies entirely inside it (V_k ⊆ S_i); a vehicle is static iff it lies inside
some spot, dynamic otherwise. :func:`classify_world` answers for one set of vehicles. :class:`OccupancyTracker`
answers for the same vehicles step after step, testing again only those that moved: each vehicle's containing
spots depend on that vehicle alone, so the answer is the one :func:`classify_world` gives, bit for bit.
"""

from __future__ import annotations

import numpy as np

from avp_world.geometry import rect_inside_rect
from avp_world.lot import LotMap


def inside_pairs(lot: LotMap, vehicle_corners: np.ndarray, tol: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """(vehicle row, spot row) of every vehicle lying inside a spot, sorted by vehicle, then spot."""
    vc = np.asarray(vehicle_corners, dtype=float).reshape(-1, 4, 2)
    sc = np.asarray(lot.spot_corners, dtype=float).reshape(-1, 4, 2)
    if vc.shape[0] == 0 or sc.shape[0] == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    # Only pairs within reach can pass: a vehicle inside a spot has its centre (the mean of its corners, an
    # affine image) inside the spot grown by tol, so within the spot's half-diagonal × (1 + tol) of its centre.
    reach = 0.5 * np.hypot(lot.spot_dims[:, 0], lot.spot_dims[:, 1]) * (1.0 + tol) + 1e-9
    gap = vc.mean(axis=1)[:, None, :] - sc.mean(axis=1)[None, :, :]
    ii, jj = np.nonzero(np.hypot(gap[..., 0], gap[..., 1]) <= reach[None])  # row-major: jj ascending per ii
    if ii.size:
        inside = rect_inside_rect(vc[ii], sc[jj], tol=tol)
        ii, jj = ii[inside], jj[inside]
    return ii.astype(np.int64), jj.astype(np.int64)


def from_pairs(n_spots: int, n_vehicles: int, ii: np.ndarray, jj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(spot_occupied, vehicle_spot) of :func:`classify_world` from its :func:`inside_pairs`, given in any order
    that keeps each vehicle's pairs in spot order (a vehicle's first pair names its lowest spot)."""
    spot_occupied = np.zeros(n_spots, dtype=bool)
    vehicle_spot = np.full(n_vehicles, -1, dtype=np.int64)
    if ii.size:
        spot_occupied[jj] = True
        first_vehicle, first = np.unique(ii, return_index=True)
        vehicle_spot[first_vehicle] = jj[first]  # the lowest row wins if spots overlap
    return spot_occupied, vehicle_spot


def classify_world(
    lot: LotMap, vehicle_corners: np.ndarray, tol: float = 1e-6
) -> tuple[np.ndarray, np.ndarray]:
    """Occupied spots and static vehicles (paper §III-A).

    Args:
        lot: the lot map.
        vehicle_corners: (N, 4, 2) corners of the vehicles to classify.
        tol: slack of the containment test as a fraction of the spot's side lengths.
    Returns:
        spot_occupied (n_spots,) bool and vehicle_spot (N,) int (the containing spot's row in the lot's
        spot arrays, -1 for a dynamic vehicle; the lowest row if spots overlap).
    """
    n = np.asarray(vehicle_corners).reshape(-1, 4, 2).shape[0]
    return from_pairs(len(lot.spot_corners), n, *inside_pairs(lot, vehicle_corners, tol))


class OccupancyTracker:
    """:func:`classify_world` of one lot's vehicles step after step, testing only the vehicles whose corners
    changed since the last call (most of a busy lot's cars stand parked). Any change in the number of vehicles
    tests them all again."""

    def __init__(self, lot: LotMap, tol: float = 1e-6) -> None:
        self.lot, self.tol = lot, tol
        self._corners: np.ndarray | None = None
        self._pairs = (np.zeros(0, np.int64), np.zeros(0, np.int64))

    def classify(self, vehicle_corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        vc = np.array(vehicle_corners, dtype=float).reshape(-1, 4, 2)
        if self._corners is None or self._corners.shape != vc.shape:
            ii, jj = inside_pairs(self.lot, vc, self.tol)
        else:
            moved = np.nonzero((vc != self._corners).any(axis=(1, 2)))[0]
            ii, jj = self._pairs
            if len(moved):
                keep = ~np.isin(ii, moved)
                mi, mj = inside_pairs(self.lot, vc[moved], self.tol)
                # each vehicle's pairs stay together and in spot order: all from_pairs needs
                ii, jj = np.concatenate([ii[keep], moved[mi]]), np.concatenate([jj[keep], mj])
        self._corners, self._pairs = vc, (ii, jj)
        return from_pairs(len(self.lot.spot_corners), vc.shape[0], ii, jj)


__all__ = ["OccupancyTracker", "classify_world", "from_pairs", "inside_pairs"]

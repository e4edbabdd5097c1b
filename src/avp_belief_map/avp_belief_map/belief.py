"""Belief map of parked cars (paper §V-B): b_t in [0, 1]^N_S, one belief per spot, in lot spot order.

b_t,i is the estimated probability that another vehicle has parked or will soon park in spot S_i.
It starts at b_-dt = 0.5 * 1 (no information) and is updated twice per step:

* eq. (7), :func:`observation_update`: b~_t,i = 0 if i in I_vac,t, 1 if i in I_occ,t, else b_t-dt,i;
* eq. (8), :func:`intention_update`: b_t,i = 1 - prod(1 - eta_k,i) over the observed dynamic vehicles k
  that have i as a candidate (i in I_can,k), for every observed vacant spot i in I_vac,t; every other
  spot keeps b~_t,i. An observed vacant spot that is nobody's candidate gets the empty product, b = 0.

Between the two updates the BEV of every observed dynamic vehicle is drawn from b~ (:mod:`.bev`): a
spot is believed occupied iff b >= beta (beta = 0.5, §VI-A).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from avp_world.lot import LotMap

#: where the belief map's update takes its evidence (pipeline.PerceptionCore; here, apart from torch, for the
#: parameter specs)
BELIEF_SOURCES = ("intent", "nawaz", "observation")

BELIEF_INIT = 0.5  # b_-dt (§V-B)
BETA = 0.5  # belief threshold: occupied iff b >= beta (§VI-A)


def spot_indices(lot: LotMap, spot_ids: Iterable[int]) -> np.ndarray:
    """Rows of ``spot_ids`` in the lot's spot arrays (int64); KeyError names an unknown id."""
    return np.fromiter((lot.spot_index(int(i)) for i in spot_ids), dtype=np.int64)


def observation_update(previous: np.ndarray, vacant_idx: np.ndarray, occupied_idx: np.ndarray) -> np.ndarray:
    """Eq. (7): the initial belief b~_t from b_t-dt and the current observation.

    Args:
        previous: (N_S,) b_t-dt.
        vacant_idx: indices of observed vacant spots I_vac,t.
        occupied_idx: indices of observed occupied spots I_occ,t.

    Returns:
        (N_S,) b~_t: 0 on I_vac,t, 1 on I_occ,t, b_t-dt elsewhere (a new array).
    """
    b = np.array(previous, dtype=float, copy=True)
    b[np.asarray(vacant_idx, dtype=np.int64)] = 0.0
    b[np.asarray(occupied_idx, dtype=np.int64)] = 1.0
    return b


def intention_update(
    b_tilde: np.ndarray,
    vacant_idx: np.ndarray,
    candidate_idx: Sequence[np.ndarray],
    probabilities: Sequence[np.ndarray],
) -> np.ndarray:
    """Eq. (8): b_t,i = 1 - prod_{k: i in I_can,k} (1 - eta_k,i) for i in I_vac,t; b~_t,i otherwise.

    Args:
        b_tilde: (N_S,) b~_t from eq. (7).
        vacant_idx: indices of I_vac,t.
        candidate_idx: per observed dynamic vehicle k, the indices of its candidate spots I_can,k.
        probabilities: per vehicle, eta_k,i aligned with ``candidate_idx[k]``.

    Returns:
        (N_S,) b_t (a new array).
    """
    if len(candidate_idx) != len(probabilities):
        raise ValueError(f"{len(candidate_idx)} candidate sets but {len(probabilities)} probability sets")
    keep = np.ones(len(b_tilde))  # prod (1 - eta) per spot; the empty product is 1
    for idx, p in zip(candidate_idx, probabilities, strict=True):
        idx = np.asarray(idx, dtype=np.int64)
        p = np.asarray(p, dtype=float)
        if idx.shape != p.shape:
            raise ValueError(f"candidate indices {idx.shape} and probabilities {p.shape} differ in shape")
        np.multiply.at(keep, idx, 1.0 - p)
    b = np.array(b_tilde, dtype=float, copy=True)
    vac = np.asarray(vacant_idx, dtype=np.int64)
    b[vac] = 1.0 - keep[vac]
    return b


class BeliefMap:
    """The belief map b_t of §V-B over ``n_spots`` spots (index = row in the lot's spot arrays).

    Use :meth:`observe` (eq. 7) then :meth:`apply_intentions` (eq. 8) once per step. ``b_tilde`` is the
    belief after eq. (7) of the current step (what the BEV is drawn from); ``values`` is b_t.
    """

    def __init__(self, n_spots: int, init: float = BELIEF_INIT, spot_ids: np.ndarray | None = None):
        if n_spots < 0:
            raise ValueError(f"n_spots must be >= 0, got {n_spots}")
        if not 0.0 <= init <= 1.0:
            raise ValueError(f"init must be in [0, 1], got {init}")
        self.init = float(init)
        self.spot_ids = np.arange(n_spots, dtype=np.int64) if spot_ids is None else np.asarray(spot_ids, np.int64)
        if len(self.spot_ids) != n_spots:
            raise ValueError(f"{len(self.spot_ids)} spot ids for {n_spots} spots")
        self._row = {int(s): k for k, s in enumerate(self.spot_ids)}
        self.values = np.full(n_spots, self.init)
        self.b_tilde = self.values.copy()
        self.vacant_idx = np.zeros(0, dtype=np.int64)
        self.occupied_idx = np.zeros(0, dtype=np.int64)

    @classmethod
    def from_lot(cls, lot: LotMap, init: float = BELIEF_INIT) -> BeliefMap:
        return cls(lot.n_spots, init, lot.spot_ids)

    def __len__(self) -> int:
        return len(self.values)

    def reset(self) -> None:
        self.values = np.full(len(self.values), self.init)
        self.b_tilde = self.values.copy()
        self.vacant_idx = np.zeros(0, dtype=np.int64)
        self.occupied_idx = np.zeros(0, dtype=np.int64)

    def indices(self, spot_ids: Iterable[int]) -> np.ndarray:
        """Rows of spot ids; KeyError names an unknown id."""
        try:
            return np.fromiter((self._row[int(s)] for s in spot_ids), dtype=np.int64)
        except KeyError as exc:
            raise KeyError(f"unknown spot id {exc.args[0]}") from None

    @property
    def observed_mask(self) -> np.ndarray:
        """Spots observed this step (I_vac,t or I_occ,t)."""
        m = np.zeros(len(self.values), dtype=bool)
        m[self.vacant_idx] = True
        m[self.occupied_idx] = True
        return m

    def observe(self, vacant_spot_ids: Iterable[int], occupied_spot_ids: Iterable[int]) -> np.ndarray:
        """Eq. (7) with this step's observed vacant / occupied spot ids; returns (a copy of) b~_t."""
        self.vacant_idx = self.indices(vacant_spot_ids)
        self.occupied_idx = self.indices(occupied_spot_ids)
        self.b_tilde = observation_update(self.values, self.vacant_idx, self.occupied_idx)
        self.values = self.b_tilde.copy()
        return self.b_tilde.copy()

    def apply_intentions(self, intentions: Iterable) -> np.ndarray:
        """Eq. (8) with the intentions (objects with ``spot_ids`` and ``spot_probabilities``) of this step's
        observed dynamic vehicles; returns (a copy of) b_t."""
        cand, prob = [], []
        for it in intentions:
            cand.append(self.indices(it.spot_ids))
            prob.append(np.asarray(it.spot_probabilities, dtype=float))
        self.values = intention_update(self.b_tilde, self.vacant_idx, cand, prob)
        return self.values.copy()

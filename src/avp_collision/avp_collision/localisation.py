"""The lot boundary the ego plans against when its own pose is an estimate (``collision.localisation_sigmas``).

The paper's ego knows its pose exactly, and §V-D asks every state to keep its footprint inside the lot, V ⊆ L. A
real ego places itself on the map with a localiser's estimate, while the other cars it detects are placed with the
same estimate and so move with it: the error falls on the map's own features, above all on the walls of L. With
noisy sensing (docs/perception.md, "Sensing") the ego plans inside

    L' = (L shrunk by m) ∪ ⋃_i (S_i ∩ L),   m = k · (σ_xy + r · σ_θ),

with σ_xy the larger standard deviation of its position estimate, σ_θ its heading's, r the footprint's half
diagonal and k = ``collision.localisation_sigmas``. The spots stay whole, so a spot at a wall can still be the goal.
Exact sensing reports no covariance and plans against L itself, as the paper does; k = 0 does the same under noise.

With ``collision.localisation_keep_start`` the ego's own estimated footprint V_0 (grown by the search's clearance,
so that a path may leave it) is kept whole too, L'' = L' ∪ (V_0 ∩ L), on the steps where L' leaves it outside. An
estimate nearer a wall than m (the entrance the ego starts at, under a drift of a few tenths of a metre) is still a
place to plan from, and a path from it must leave into L' (``avp_motion.planner_inputs``).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from avp_world.lot import LotMap

MARGIN_STEP = 0.01  # m: margins are rounded to this, so a steady localiser gives one boundary an episode


def localisation_margin(covariance: np.ndarray | None, length: float, width: float, sigmas: float) -> float:
    """m of the module docstring (0 without a covariance or with ``sigmas`` 0), rounded to ``MARGIN_STEP``."""
    if covariance is None or sigmas <= 0:
        return 0.0
    cov = np.asarray(covariance, dtype=float).reshape(3, 3)
    sigma_xy = math.sqrt(max(0.0, float(np.linalg.eigvalsh(cov[:2, :2]).max())))
    sigma_th = math.sqrt(max(0.0, float(cov[2, 2])))
    m = sigmas * (sigma_xy + 0.5 * math.hypot(length, width) * sigma_th)
    return round(m / MARGIN_STEP) * MARGIN_STEP


def localised_lot(lot: LotMap, margin: float, keep: np.ndarray | None = None, grow: float = 0.0) -> LotMap:
    """``lot`` with its boundary L replaced by L' (module docstring), or L'' with ``keep`` (a footprint's (4, 2)
    corners, grown by ``grow`` on every side, kept whole); ``lot`` itself for ``margin`` <= 0."""
    if margin <= 0:
        return lot
    from shapely.geometry import Polygon
    from shapely.geometry.polygon import orient
    from shapely.ops import unary_union

    region = Polygon(lot.boundary)
    shrunk = region.buffer(-margin, join_style="mitre")
    spots = [Polygon(c).intersection(region) for c in lot.spot_corners]
    if keep is not None:
        spots.append(Polygon(keep).buffer(grow, join_style="mitre").intersection(region))
    merged = unary_union([shrunk, *spots])
    pieces = list(getattr(merged, "geoms", [merged]))
    biggest = max(pieces, key=lambda g: g.area)  # spots cut off from the rest could not be reached anyway
    ring = np.asarray(orient(biggest, 1.0).exterior.coords)[:-1]  # counter-clockwise, as LotMap.boundary is
    return replace(lot, boundary=ring, _index={})


def footprint_inside(lot: LotMap, corners: np.ndarray) -> bool:
    """Whether a footprint's (4, 2) corners lie inside ``lot``'s boundary (its L')."""
    from shapely.geometry import Polygon

    return bool(Polygon(lot.boundary).contains(Polygon(corners)))

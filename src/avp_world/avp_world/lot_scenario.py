"""Where the §VI-A scenario generator puts things on a lot: the optional ``scenario:`` block of a lot YAML, and the
defaults derived from the lot's geometry when the block is absent (ROS-free).

The paper's protocol (§VI-A) on its lot: the ego starts at the entrance ("the ego agent starts at the top of the
middle road"), the contested spots are the bottom rows of the two middle columns (the far end of the ego's road),
and "2 vacant spots on the sides" are the fallbacks. On any lot the same roles are read from the geometry:

* **ego start**: the end of the road nearest the entrance (the *first road*), facing along it;
* **contested spots**: of the spots bordering the first road, the ``CONTESTED_PER_SIDE`` farthest along it on
  each side (ids ascending);
* **fallback groups**: the spots bordering other roads, one group per road (ordered farthest along the first road
  first, so that ``scenario.outer_row_min..max`` of avp_sim picks the rows level with the contested ones), the two
  largest groups (the one group twice where only one other road has spots); one vacant spot is drawn from each,
  all distinct;
* **aisle width**: the first road's width (ParkSim's maneuvers are made for it).

On the paper lot this gives exactly the ids the generator used before lots could say it (tests/test_lots.py).
A lot's ``scenario:`` block may set any of them::

    scenario:
      ego_start: [21.5, 38.0, -1.5707963267948966]
      contested_spot_ids: [10, 11, 12, 13, 14, 20, 21, 22, 23, 24]
      fallback_spot_groups: [[0, 1, 2, 3, 4, 5, 6, 7, 8, 9], [30, 31, 32, 33, 34, 35, 36, 37, 38, 39]]
      aisle_width: 7.0
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from avp_world.lot_scenario_block import SCENARIO_KEYS

if TYPE_CHECKING:
    from avp_world.lot import LotMap

CONTESTED_PER_SIDE = 5  # contested spots on each side of the first road (the paper lot: 5 bottom rows)
N_FALLBACK_GROUPS = 2  # "2 vacant spots on the sides" (§VI-A)


@dataclass(frozen=True)
class LotScenario:
    """The roles of a lot's places in the §VI-A generator (see the module docstring)."""

    ego_start: tuple[float, float, float]
    contested_spot_ids: tuple[int, ...]
    fallback_spot_groups: tuple[tuple[int, ...], ...]
    aisle_width: float


def first_road(lot: LotMap) -> tuple[int, np.ndarray, np.ndarray]:
    """(row of the road nearest the entrance, its end nearer the entrance, unit direction away from it)."""
    e = np.asarray(lot.entrance, dtype=float)
    best, best_d = 0, math.inf
    for i, (a, b) in enumerate(lot.road_segments):
        ab = b - a
        t = float(np.clip((e - a) @ ab / (ab @ ab), 0.0, 1.0))
        d = float(np.hypot(*(a + t * ab - e)))
        if d < best_d - 1e-9:
            best, best_d = i, d
    a, b = lot.road_segments[best]
    near, far = (a, b) if np.hypot(*(a - e)) <= np.hypot(*(b - e)) else (b, a)
    u = (far - near) / np.hypot(*(far - near))
    return best, near.copy(), u


def spot_aisles(lot: LotMap, tol: float = 0.05) -> np.ndarray:
    """(N_S,) index of the road each spot borders, -1 if none.

    Spot i borders road j when the point p_i - u_i (l_i / 2 + w_j / 2) (u_i: the spot's heading, which points
    away from its road, §II-A) lies on the centre line C_j (or its extension by w_j / 2, the end of the road's
    swept square) and C_j is perpendicular to u_i.
    """
    out = np.full(lot.n_spots, -1, dtype=np.int64)
    if not lot.roads:
        return out
    poses, dims = lot.spot_poses, lot.spot_dims
    u = np.stack([np.cos(poses[:, 2]), np.sin(poses[:, 2])], axis=1)
    best = np.full(lot.n_spots, np.inf)
    for j, r in enumerate(lot.roads):
        a, b = np.asarray(r.start, float), np.asarray(r.end, float)
        d = (b - a) / r.length
        front = poses[:, :2] - u * (dims[:, :1] / 2.0 + r.width / 2.0)
        t = (front - a) @ d
        off = np.abs((front - a) @ np.array([-d[1], d[0]]))
        perp = np.abs(u @ d) < 1e-3
        reach = r.width / 2.0 + tol  # the road's swept square reaches w / 2 beyond its end points
        ok = perp & (off < tol) & (t >= -reach) & (t <= r.length + reach) & (off < best)
        out[ok] = j
        best[ok] = off[ok]
    return out


def derive_lot_scenario(lot: LotMap) -> LotScenario:
    """The roles read from the geometry (module docstring)."""
    road, near, u = first_road(lot)
    border = spot_aisles(lot)
    rel = lot.spot_poses[:, :2] - near
    along = rel @ u
    side = np.sign(u[0] * rel[:, 1] - u[1] * rel[:, 0])
    contested: list[int] = []
    for sgn in (1.0, -1.0):
        rows = [i for i in np.flatnonzero((border == road) & (side == sgn))]
        rows.sort(key=lambda i: (-along[i], int(lot.spot_ids[i])))
        contested += [int(lot.spot_ids[i]) for i in rows[:CONTESTED_PER_SIDE]]
    groups: list[tuple[int, list[int]]] = []
    for r in range(len(lot.roads)):
        if r == road:
            continue
        rows = sorted(np.flatnonzero(border == r), key=lambda i: (-along[i], int(lot.spot_ids[i])))
        if rows:
            groups.append((r, [int(lot.spot_ids[i]) for i in rows]))
    largest = sorted(groups, key=lambda g: (-len(g[1]), g[0]))[:N_FALLBACK_GROUPS]
    fallback = tuple(tuple(g) for _, g in sorted(largest))
    if 0 < len(fallback) < N_FALLBACK_GROUPS:  # one other row only: both fallbacks from it (distinct spots)
        fallback = fallback * N_FALLBACK_GROUPS
    return LotScenario(ego_start=(float(near[0]), float(near[1]), math.atan2(u[1], u[0])),
                       contested_spot_ids=tuple(sorted(contested)), fallback_spot_groups=fallback,
                       aisle_width=float(lot.roads[road].width))


def lot_scenario(lot: LotMap) -> LotScenario:
    """The lot's ``scenario:`` block, its missing keys filled from :func:`derive_lot_scenario`."""
    block = getattr(lot, "scenario", None) or {}
    if not block:
        return derive_lot_scenario(lot)
    derived = derive_lot_scenario(lot)
    return LotScenario(**{k: block.get(k, getattr(derived, k)) for k in SCENARIO_KEYS})

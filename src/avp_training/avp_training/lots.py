"""Parking lots for the intent model's training data: the DLP-derived lot and seeded random lots.

None of them is the paper's experiment lot (§VI-A), which is kept for testing only.

* :func:`load_dlp_lot` — ``maps/dlp_west.yaml``: the west half of the Dragon Lake Parking lot (196 spots)
  from the reference sheet's map facts (§3.4; the file's header says what was taken and what was chosen).
* :func:`random_lot` — a seeded grid lot: ``n_aisles`` parallel aisles with double-loaded blocks of spots
  between them (every spot borders exactly one aisle and faces away from it, §II-A), optional single-loaded
  rows along the outer aisles, connector roads at both ends (and optionally one in the middle) so that
  every aisle is part of a loop, the entrance at the end of an aisle or of a connector road, the whole lot
  rotated by a random angle. Spot sizes and aisle widths come from small sets for which ParkSim's 8
  maneuvers exist (:mod:`avp_scenario.maneuvers`, one cached library per scene geometry).
* :func:`spot_aisles` — for every spot, the road it borders (its aisle): what the maneuver library needs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from avp_world.lot import LotMap, load_lot, lot_from_dict
from avp_world.lot_scenario import spot_aisles  # noqa: F401 - re-exported

MAPS_DIR = Path(__file__).resolve().parent / "maps"
DLP_LOT_FILE = MAPS_DIR / "dlp_west.yaml"


def load_dlp_lot() -> LotMap:
    """The DLP-derived training lot (``avp_training/maps/dlp_west.yaml``)."""
    return load_lot(DLP_LOT_FILE)


@dataclass(frozen=True)
class RandomLotParams:
    """Ranges of the random grid lots (all draws uniform)."""

    n_aisles: tuple[int, int] = (2, 4)  # parallel aisles
    n_cols: tuple[int, int] = (5, 14)  # spots per row between two connector roads
    spot_sizes: tuple[tuple[float, float], ...] = ((5.5, 2.75), (5.3, 2.6))  # (length, width) [m]
    aisle_widths: tuple[float, ...] = (7.0, 7.2)  # [m], also the connector roads' width
    p_outer_row: float = 0.5  # probability of a single-loaded row beyond each outer aisle
    p_middle_road: float = 0.4  # probability of a third connector road splitting the rows
    rotate: bool = True  # rotate the lot by a random angle in [0, 2 pi)


def _rot(points: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.asarray(points, dtype=float) @ np.array([[c, s], [-s, c]])


def random_lot(seed: int, params: RandomLotParams = RandomLotParams()) -> LotMap:
    """A seeded random grid lot (see the module docstring); validated by :func:`avp_world.lot.lot_from_dict`.

    Local frame before rotation: aisles along x at increasing y, connector roads along y.
    """
    rng = np.random.default_rng(int(seed))
    n_aisles = int(rng.integers(params.n_aisles[0], params.n_aisles[1] + 1))
    length, width = params.spot_sizes[int(rng.integers(len(params.spot_sizes)))]
    w = float(params.aisle_widths[int(rng.integers(len(params.aisle_widths)))])
    middle = bool(rng.random() < params.p_middle_road)
    segs = [int(rng.integers(params.n_cols[0], params.n_cols[1] + 1)) for _ in range(2 if middle else 1)]
    outer_bottom = bool(rng.random() < params.p_outer_row)
    outer_top = bool(rng.random() < params.p_outer_row)

    # connector roads (x) and the spans of spots between them
    xs = [w / 2.0]
    spans = []
    for n in segs:
        x0 = xs[-1] + w / 2.0
        spans.append((x0, n))
        xs.append(x0 + n * width + w / 2.0)
    x_max = xs[-1] + w / 2.0
    # aisles (y), bottom to top
    y = length if outer_bottom else 0.0
    ys = []
    for j in range(n_aisles):
        ys.append(y + w / 2.0)
        y += w + (2.0 * length if j < n_aisles - 1 else 0.0)
    y_max = y + (length if outer_top else 0.0)

    rows: list[tuple[float, float]] = []  # (centre y, heading)
    if outer_bottom:
        rows.append((ys[0] - w / 2.0 - length / 2.0, -math.pi / 2))
    for j in range(n_aisles - 1):
        rows.append((ys[j] + w / 2.0 + length / 2.0, math.pi / 2))  # borders aisle j, faces away (north)
        rows.append((ys[j + 1] - w / 2.0 - length / 2.0, -math.pi / 2))  # borders aisle j + 1 (south)
    if outer_top:
        rows.append((ys[-1] + w / 2.0 + length / 2.0, math.pi / 2))

    roads = [((xs[0], yy), (xs[-1], yy)) for yy in ys]  # aisles
    roads += [((x, ys[0]), (x, ys[-1])) for x in xs]  # connectors

    # entrance: at the end of an aisle (side) or of a connector road (top / bottom)
    kind = ("side", "top", "bottom")[int(rng.integers(3))]
    if kind == "side":
        yy = ys[int(rng.integers(n_aisles))]
        entrance = (0.0, yy) if rng.random() < 0.5 else (x_max, yy)
    else:
        x = xs[int(rng.integers(len(xs)))]
        if kind == "top":
            entrance = (x, y_max)
            if outer_top:  # connector extended through the gap beside the outer row
                roads.append(((x, ys[-1]), (x, y_max - w / 2.0)))
        else:
            entrance = (x, 0.0)
            if outer_bottom:
                roads.append(((x, ys[0]), (x, w / 2.0)))

    boundary = np.array([[0.0, 0.0], [x_max, 0.0], [x_max, y_max], [0.0, y_max]])
    angle = float(rng.uniform(0.0, 2.0 * math.pi)) if params.rotate else 0.0
    shift = -_rot(boundary, angle).min(axis=0)

    def tf(p) -> list[float]:
        q = _rot(np.asarray(p, dtype=float)[None], angle)[0] + shift
        return [round(float(q[0]), 6), round(float(q[1]), 6)]

    spots = []
    for cy, heading in rows:
        for x0, n in spans:
            for k in range(n):
                spots.append({"center": tf((x0 + (k + 0.5) * width, cy)),
                              "heading": float(math.remainder(heading + angle, 2.0 * math.pi)),
                              "length": length, "width": width})
    data = {
        "name": f"random_{seed}",
        "boundary": [tf(p) for p in boundary],
        "entrance": tf(entrance),
        "roads": [{"id": i, "start": tf(a), "end": tf(b), "width": w} for i, (a, b) in enumerate(roads)],
        "spots": spots,
    }
    return lot_from_dict(data, source=f"<random lot {seed}>")

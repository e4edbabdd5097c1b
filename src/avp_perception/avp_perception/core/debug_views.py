"""Debug views of the belief node (ROS-free): the belief map as an occupancy grid, the BEVs tiled.

**debug/occupancy** (nav_msgs/OccupancyGrid) shows the belief map b_t of §V-B. A cell of side ``resolution``
covering the lot's bounding box holds (in OccupancyGrid's int8 convention):

* inside spot S_i (cell centre in the spot rectangle): round(100 b_t,i) once S_i has been observed at least
  once this episode (i in I_vac or I_occ at some step, eq. 7), else -1 (unknown: b_t,i is still the prior
  b_-dt — drawing 50 there would look like information);
* elsewhere inside the lot polygon L (roads, kerbs between spots): 0 (the map is known a priori, §II-A);
* outside L: 100 (not drivable).

Row i, column j is the cell whose centre is origin + ((j + 0.5) res, (i + 0.5) res), row-major from the
origin (x_min, y_min) of L's bounding box, as OccupancyGrid expects. The cell -> spot table is built once
per lot (:func:`grid_layout`), so a grid costs one gather per step.

**debug/bev** (sensor_msgs/Image, rgb8): :func:`tile_bevs` puts the unmarked BEV I_k,0 (§V-B) of every
observed dynamic vehicle side by side, in observation order, separated by ``gap`` white columns; an image
of one black tile when no dynamic vehicle is observed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from avp_world.geometry import points_in_rects, polygon_contains_points
from avp_world.lot import LotMap

UNKNOWN = -1
FREE = 0
OCCUPIED = 100


@dataclass(frozen=True)
class GridLayout:
    """Which spot (row in the lot's spot arrays, -1 none) and whether L covers each cell centre."""

    resolution: float
    origin: tuple[float, float]  # (x, y) of the grid's lower-left corner
    width: int  # cells along x
    height: int  # cells along y
    spot_row: np.ndarray  # (height, width) int64
    inside: np.ndarray  # (height, width) bool: cell centre inside L

    def cell_centres(self) -> np.ndarray:
        """(height, width, 2) world coordinates of the cell centres."""
        xs = self.origin[0] + (np.arange(self.width) + 0.5) * self.resolution
        ys = self.origin[1] + (np.arange(self.height) + 0.5) * self.resolution
        gx, gy = np.meshgrid(xs, ys)
        return np.stack([gx, gy], axis=-1)


def grid_layout(lot: LotMap, resolution: float) -> GridLayout:
    """The cell -> spot table of ``lot`` at ``resolution`` metres per cell (ValueError if not > 0)."""
    if not (math.isfinite(resolution) and resolution > 0):
        raise ValueError(f"resolution must be a finite number > 0, got {resolution!r}")
    xmin, ymin, xmax, ymax = lot.bounds()
    width = max(1, int(math.ceil((xmax - xmin) / resolution - 1e-9)))
    height = max(1, int(math.ceil((ymax - ymin) / resolution - 1e-9)))
    layout = GridLayout(float(resolution), (float(xmin), float(ymin)), width, height,
                        np.full((height, width), -1, dtype=np.int64), np.zeros((height, width), dtype=bool))
    c = layout.cell_centres().reshape(-1, 2)
    inside = polygon_contains_points(np.asarray(lot.boundary, dtype=float), c)
    layout.spot_row[:] = _spot_rows(layout, lot)
    layout.inside[:] = inside.reshape(height, width)
    return layout


def _spot_rows(layout: GridLayout, lot: LotMap) -> np.ndarray:
    """(height, width) row of the lowest spot whose rectangle holds the cell centre, -1 none. Each spot tests only
    the cells of its bounding box (grown by a cell): a centre inside the rectangle lies in its box."""
    row = np.full((layout.height, layout.width), -1, dtype=np.int64)
    centres = layout.cell_centres()
    res, (x0, y0) = layout.resolution, layout.origin
    for j, corners in enumerate(np.asarray(lot.spot_corners, dtype=float)):
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        c0 = max(int(math.floor((lo[0] - x0) / res)) - 1, 0)
        c1 = min(int(math.ceil((hi[0] - x0) / res)) + 1, layout.width)
        r0 = max(int(math.floor((lo[1] - y0) / res)) - 1, 0)
        r1 = min(int(math.ceil((hi[1] - y0) / res)) + 1, layout.height)
        if c0 >= c1 or r0 >= r1:
            continue
        hit = points_in_rects(centres[r0:r1, c0:c1], corners, tol=0.0)
        window = row[r0:r1, c0:c1]
        window[hit & (window < 0)] = j  # ascending j: the lowest row wins where spots overlap
    return row


def belief_grid(layout: GridLayout, beliefs: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """(height, width) int8 occupancy values of b_t (see the module docstring).

    Args:
        layout: from :func:`grid_layout` for the same lot.
        beliefs: (N_S,) b_t in lot spot order.
        seen: (N_S,) bool, spots observed at least once this episode.
    """
    b = np.clip(np.rint(np.asarray(beliefs, dtype=float) * 100.0), 0, 100).astype(np.int8)
    per_spot = np.where(np.asarray(seen, dtype=bool), b, np.int8(UNKNOWN)).astype(np.int8)
    out = np.where(layout.inside, np.int8(FREE), np.int8(OCCUPIED)).astype(np.int8)
    in_spot = layout.spot_row >= 0
    out[in_spot] = per_spot[layout.spot_row[in_spot]]
    return out


def tile_bevs(images: list[np.ndarray], size_px: int, gap: int = 2) -> np.ndarray:
    """(size_px, n size_px + (n - 1) gap, 3) uint8: the (size_px, size_px, 3) images side by side."""
    if not images:
        return np.zeros((size_px, size_px, 3), dtype=np.uint8)
    n = len(images)
    out = np.full((size_px, n * size_px + (n - 1) * gap, 3), 255, dtype=np.uint8)
    for k, img in enumerate(images):
        x0 = k * (size_px + gap)
        out[:, x0:x0 + size_px] = img
    return out

"""A static world built from another one's grid: the same rectangles and more (the detour round's world, §V-D-3: the
step's world with the standing agents added), the same grid, distance field and signed field as a full build.

Adding obstacles only lowers the distance to them: the new distance transform is the old one's minimum with the
distance to the added rectangles' cells, which is computed in a window around each added rectangle as wide as the
largest distance of the old field (outside it the old value is the smaller). The depth inside obstacles is kept
only up to :attr:`StaticWorld.depth_cap` (no caller asks more than whether a point lies deeper than
``sure_depth``); it changes only within ``depth_cap`` of an added cell, and there a window ``depth_cap`` wider
holds every free cell that decides it. Exact, not approximate: tests/test_world_extend.py compares every array with
a full build's.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

RASTER_SHIFT = 8  # fractional bits of the rasteriser's vertex coordinates (StaticWorld's grid and this)


def extend_grid(world, base) -> bool:
    """Fill ``world``'s grid from ``base``'s when ``world``'s rectangles are ``base``'s followed by others (and the
    lot, ego and settings are the same); False (nothing done) otherwise."""
    n = len(base.rect_poses)
    if (base.lot is not world.lot or base.settings != world.settings or len(world.rect_poses) < n
            or (base.length, base.width) != (world.length, world.width)
            or not np.array_equal(world.rect_poses[:n], base.rect_poses)
            or not np.array_equal(world.rect_dims[:n], base.rect_dims)):
        return False
    world._grid_frame()
    poses, dims = world.rect_poses[n:], world.rect_dims[n:]
    grid = base.grid.copy()
    polygons = world._raster_rects(grid, poses, dims)
    world.grid = grid
    edt, depth, sdf = base.edt.copy(), base.depth.copy(), base._sdf_flat.copy().reshape(grid.shape)
    h, w = grid.shape
    res = world.res
    reach = int(math.ceil(base.edt_max / res)) + 2  # cells: no old distance is longer
    cap = int(math.ceil(world.depth_cap / res)) + 2
    boxes = []  # per added rectangle: its vertices (raster units) and its cells' bounding box
    for pts in polygons:
        lo, hi = (pts.min(axis=0) >> RASTER_SHIFT) - 2, (pts.max(axis=0) >> RASTER_SHIFT) + 3  # (col, row)
        r0, r1, c0, c1 = max(int(lo[1]), 0), min(int(hi[1]), h), max(int(lo[0]), 0), min(int(hi[0]), w)
        if r0 < r1 and c0 < c1:  # else off the grid
            boxes.append((pts, (r0, r1, c0, c1)))
    if not boxes:
        world.edt, world.depth, world._sdf_flat = edt, depth, base._sdf_flat.copy()
        return True
    windows = [_grown(b, reach, h, w) for _, b in boxes]
    union = (min(x[0] for x in windows), max(x[1] for x in windows), min(x[2] for x in windows),
             max(x[3] for x in windows))
    if sum(_area(x) for x in windows) > _area(union):  # one transform over them all is cheaper
        _lower_edt(edt, [pts for pts, _ in boxes], union, res)
    else:
        for (pts, _), win in zip(boxes, windows, strict=True):
            _lower_edt(edt, [pts], win, res)
    for _, b in boxes:  # depth where it may have changed (within cap of the cells), from a window cap wider
        i0, i1, j0, j1 = _grown(b, cap, h, w)
        o0, o1, p0, p1 = _grown(b, 2 * cap, h, w)
        dd = cv2.distanceTransform(grid[o0:o1, p0:p1], cv2.DIST_L2, cv2.DIST_MASK_PRECISE).astype(np.float32) * res
        depth[i0:i1, j0:j1] = np.minimum(dd[i0 - o0:i1 - o0, j0 - p0:j1 - p0], np.float32(world.depth_cap))
    for win in windows:
        u0, u1, v0, v1 = win  # covers the depth windows too (reach >= cap)
        sdf[u0:u1, v0:v1] = edt[u0:u1, v0:v1] - depth[u0:u1, v0:v1]
    world.edt, world.depth = edt, depth
    world._sdf_flat = sdf.ravel()
    return True


def _grown(box: tuple[int, int, int, int], by: int, h: int, w: int) -> tuple[int, int, int, int]:
    r0, r1, c0, c1 = box
    return max(r0 - by, 0), min(r1 + by, h), max(c0 - by, 0), min(c1 + by, w)


def _area(box: tuple[int, int, int, int]) -> int:
    return (box[1] - box[0]) * (box[3] - box[2])


def _lower_edt(edt: np.ndarray, polygons: list[np.ndarray], win: tuple[int, int, int, int], res: float) -> None:
    """``edt`` lowered, within ``win``, to the distance to the cells of ``polygons`` (raster units)."""
    a0, a1, b0, b1 = win
    away = np.ones((a1 - a0, b1 - b0), dtype=np.uint8)
    shift = np.array([b0, a0], dtype=np.int32) << RASTER_SHIFT
    for pts in polygons:  # one call each, as StaticWorld rasterises
        cv2.fillPoly(away, [pts - shift], 0, lineType=cv2.LINE_8, shift=RASTER_SHIFT)
    if away.all():
        return
    d = cv2.distanceTransform(away, cv2.DIST_L2, cv2.DIST_MASK_PRECISE).astype(np.float32) * res
    np.minimum(edt[a0:a1, b0:b1], d, out=edt[a0:a1, b0:b1])

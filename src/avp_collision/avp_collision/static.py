"""Collision checking of the ego footprint for the planner of §V-D (ROS-free, vectorised).

**Static world** (:class:`StaticWorld`, rebuilt once per decision step): what the Hybrid A* of §V-D must
avoid, i.e. V_0,τ ⊆ L and V_0,τ ∩ S_i = ∅ for every spot believed occupied (b_t,i >= β), plus the observed
static vehicles; the goal spot is never drawn. Obstacles are kept twice:

* exactly, as oriented rectangles (spots drawn as full spot rectangles, vehicles as their rectangles) and
  the lot polygon L;
* as an occupancy grid (``grid_resolution``; outside L is occupied) and its Euclidean distance transform
  (``cv2.distanceTransform``). Obstacles are rasterised grown by a cell diagonal (so every cell containing
  an obstacle point is marked whatever the rasteriser's edge rule), hence the distance from any point q to
  the obstacles is at least EDT(cell of q) - 2h, h being half a cell diagonal.

A batch of poses is checked in two stages: the car is covered by ``n_discs`` discs along its axis; a pose
whose every disc clears the EDT by radius + margin + 2h is free (conservative, one array lookup per disc).
The remaining poses (near obstacles) get an exact separating-axis test against the rectangles within reach
and an exact test of the corners against L shrunk by the margin. "Free with margin m" means: for every
obstacle some separating axis shows a gap > m (which implies Euclidean distance > m), and the footprint
lies in L shrunk by m.

**Dynamic obstacles** (predicted agents) are :class:`avp_collision.dynamic.DynamicObstacles`, re-exported here.
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np

from avp_collision.dynamic import DynamicObstacles
from avp_collision.settings import CollisionSettings
from avp_collision.world_extend import RASTER_SHIFT, extend_grid

__all__ = ["StaticWorld", "DynamicObstacles", "merge_rects", "merge_rects_after"]
from avp_world.geometry import points_in_rects, polygon_contains_points, rect_corners, segments_intersect
from avp_world.lot import LotMap


def _disc_layout(length: float, width: float, n: int) -> tuple[np.ndarray, float]:
    """Offsets along the axis and radius of ``n`` equal discs covering a length x width rectangle."""
    seg = length / n
    offsets = -0.5 * length + seg * (np.arange(n) + 0.5)
    return offsets, math.hypot(0.5 * seg, 0.5 * width)


def _union(a: tuple, b: tuple, tol: float) -> tuple | None:
    """The rectangle (x, y, theta, length, width) that is the union of ``a`` and ``b``, if it is one (parallel,
    sharing a full edge), in ``a``'s frame; else None."""
    xi, yi, ti, li, wi = a
    xj, yj, tj, lj, wj = b
    if abs(math.sin(tj - ti)) > tol:
        return None
    ci, si = math.cos(ti), math.sin(ti)
    dx, dy = xj - xi, yj - yi
    lon, lat = ci * dx + si * dy, -si * dx + ci * dy
    if abs(lj - li) < tol and abs(lon) < tol and abs(abs(lat) - 0.5 * (wi + wj)) < tol:
        off = (0.5 * (wj - wi) if lat > 0 else -0.5 * (wj - wi)) * 0.5  # centre of the union
        mid = 0.5 * lat + off
        return (xi - si * mid, yi + ci * mid, ti, li, wi + wj)
    if abs(wj - wi) < tol and abs(lat) < tol and abs(abs(lon) - 0.5 * (li + lj)) < tol:
        off = (0.5 * (lj - li) if lon > 0 else -0.5 * (lj - li)) * 0.5
        mid = 0.5 * lon + off
        return (xi + ci * mid, yi + si * mid, ti, li + lj, wi)
    return None


def merge_rects(poses: np.ndarray, dims: np.ndarray, tol: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Merge rectangles whose union is exactly a rectangle (parallel, sharing a full edge), repeatedly.

    Adjacent occupied spots of a row (and back-to-back rows) become one rectangle, so the exact test
    compares each pose with a handful of rectangles instead of one per spot. The union is unchanged.

    The merges happen in the order of a rescan from the first pair after each merge (the first mergeable pair
    (i, j), i < j, in lexicographic order; the merged rectangle takes i's place), without rescanning: after a
    merge into i only the pairs (k, i), k < i, and (i, j) can have become mergeable (the DLP lot's ~300 occupied
    spots: 155 ms a call with full rescans, a few ms now; same rectangles).
    """
    rects = [(float(p[0]), float(p[1]), float(p[2]), float(d[0]), float(d[1]))
             for p, d in zip(np.asarray(poses).reshape(-1, 3), np.asarray(dims).reshape(-1, 2), strict=True)]
    i, j = 0, 1
    while i < len(rects):
        if j >= len(rects):
            i, j = i + 1, i + 2
            continue
        new = _union(rects[i], rects[j], tol)
        if new is None:
            j += 1
            continue
        rects[i] = new
        del rects[j]
        k = next((k for k in range(i) if _union(rects[k], rects[i], tol) is not None), None)
        while k is not None:  # an earlier rectangle merges with the grown one: that is the next merge
            rects[k] = _union(rects[k], rects[i], tol)
            del rects[i]
            i = k
            k = next((k for k in range(i) if _union(rects[k], rects[i], tol) is not None), None)
        j = i + 1
    out = np.array(rects, dtype=float).reshape(-1, 5)
    return out[:, :3].copy(), out[:, 3:].copy()


def merge_rects_after(poses: np.ndarray, dims: np.ndarray, n_base: int, cache: dict | None = None,
                      tol: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """:func:`merge_rects` of all the rectangles when the first ``n_base`` (the believed-occupied spots, the same
    step after step) are merged once and cached: the same rectangles, in the same order.

    Exact because a rectangle that is parallel (within ``tol``) to no base rectangle and to no other rectangle
    after the base can never merge (every merged rectangle keeps the heading of one of the base's): the full merge
    then leaves those rectangles as they are, after the merged base. Otherwise the full merge runs.
    """
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    dims = np.asarray(dims, dtype=float).reshape(-1, 2)
    rest_th = poses[n_base:, 2]
    if cache is None or not len(rest_th) or n_base <= 0:
        return merge_rects(poses, dims, tol)
    base_th = np.unique(poses[:n_base, 2])
    if (np.abs(np.sin(rest_th[:, None] - base_th[None, :])) <= tol).any():
        return merge_rects(poses, dims, tol)
    if len(rest_th) > 1:
        pair = np.abs(np.sin(rest_th[:, None] - rest_th[None, :])) <= tol
        np.fill_diagonal(pair, False)
        if pair.any():
            return merge_rects(poses, dims, tol)
    key = (poses[:n_base].tobytes(), dims[:n_base].tobytes(), tol)
    base = cache.get(key)
    if base is None:
        base = merge_rects(poses[:n_base], dims[:n_base], tol)
        cache[key] = base
        while len(cache) > 8:
            cache.pop(next(iter(cache)))
    return np.concatenate([base[0], poses[n_base:]]), np.concatenate([base[1], dims[n_base:]])


def _is_convex_ccw(poly: np.ndarray) -> bool:
    d1 = np.roll(poly, -1, axis=0) - poly
    d2 = np.roll(d1, -1, axis=0)
    cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    return bool((cross >= -1e-12).all())


class _Boundary:
    """Exact test "footprint inside L shrunk by m" (half-planes if L is convex, else a general test)."""

    def __init__(self, polygon: np.ndarray):
        poly = np.asarray(polygon, dtype=float)
        area2 = float(np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1]))
        if area2 < 0:
            poly = poly[::-1]
        self.polygon = poly
        self.convex = _is_convex_ccw(poly)
        e = np.roll(poly, -1, axis=0) - poly
        n = np.stack([-e[:, 1], e[:, 0]], axis=1)
        n /= np.linalg.norm(n, axis=1, keepdims=True)  # inward normals of a ccw polygon
        self.normals = n
        self.offsets = np.einsum("ij,ij->i", n, poly)
        self._shrunk: dict[float, list[np.ndarray]] = {}

    def _shrunk_rings(self, margin: float) -> list[np.ndarray]:
        if margin not in self._shrunk:
            from shapely.geometry import Polygon

            g = Polygon(self.polygon).buffer(-margin, join_style="mitre") if margin > 0 else Polygon(self.polygon)
            geoms = getattr(g, "geoms", [g])
            self._shrunk[margin] = [np.asarray(p.exterior.coords)[:-1] for p in geoms if not p.is_empty]
        return self._shrunk[margin]

    def inside(self, corners: np.ndarray, margin: float) -> np.ndarray:
        """corners (N, 4, 2) -> (N,) bool."""
        if self.convex:
            d = np.einsum("nkd,ed->nke", corners, self.normals) - self.offsets
            return (d >= margin).all(axis=(1, 2))
        ok = np.zeros(len(corners), dtype=bool)
        for ring in self._shrunk_rings(margin):
            inside = polygon_contains_points(ring, corners).all(-1)
            # no ring vertex strictly inside the footprint and no ring edge crossing a footprint edge
            vin = points_in_rects(ring[None, :, :], corners[:, None, :, :], tol=-1e-9).any(-1)
            a0, a1 = ring, np.roll(ring, -1, axis=0)
            c0, c1 = corners, np.roll(corners, -1, axis=1)
            cross = segments_intersect(c0[:, :, None], c1[:, :, None], a0[None, None], a1[None, None])
            ok |= inside & ~vin & ~cross.any(axis=(1, 2))
        return ok


class StaticWorld:
    """Static obstacles of one decision step (see the module docstring).

    Args:
        lot: the lot map (its boundary is L).
        rect_poses, rect_dims: (K, 3) centres/headings and (K, 2) length/width of obstacle rectangles.
        length, width: the ego footprint.
        settings: grid resolution, disc count.
        n_base, merge_cache: the first ``n_base`` rectangles are merged once per ``merge_cache`` (a dict the owner
            keeps; :func:`merge_rects_after`) — the same world, built faster when only the others change.
        base: a world of the same lot and ego whose rectangles are the first of this one's (after merging): its
            grid is extended by the others (:mod:`avp_collision.world_extend`) — the same world, built faster.
    """

    def __init__(
        self,
        lot: LotMap,
        rect_poses: np.ndarray,
        rect_dims: np.ndarray,
        length: float,
        width: float,
        settings: CollisionSettings = CollisionSettings(),
        n_base: int = 0,
        merge_cache: dict | None = None,
        base: StaticWorld | None = None,
    ):
        self.lot = lot
        self.settings = settings
        self.key = None  # set by the owner (cache key)
        self.length, self.width = float(length), float(width)
        self.half_l, self.half_w = 0.5 * self.length, 0.5 * self.width
        self.circum = math.hypot(self.half_l, self.half_w)
        self.obstacle_poses = np.asarray(rect_poses, dtype=float).reshape(-1, 3)
        self.obstacle_dims = np.asarray(rect_dims, dtype=float).reshape(-1, 2)
        self.rect_poses, self.rect_dims = merge_rects_after(self.obstacle_poses, self.obstacle_dims, n_base,
                                                            merge_cache)
        self.rect_half = 0.5 * self.rect_dims
        self.rect_cos = np.cos(self.rect_poses[:, 2])
        self.rect_sin = np.sin(self.rect_poses[:, 2])
        self.rect_circum = np.hypot(self.rect_half[:, 0], self.rect_half[:, 1])
        self.boundary = _Boundary(lot.boundary)
        self.disc_offsets, self.disc_radius = _disc_layout(self.length, self.width, settings.n_discs)
        if base is None or not extend_grid(self, base):
            self._build_grid()

    # ------------------------------------------------------------------ grid
    def _build_grid(self) -> None:
        self._grid_frame()
        grid = np.ones((self.shape[0], self.shape[1]), dtype=np.uint8)  # 1 = occupied
        for ring in self.boundary._shrunk_rings(self.grow):
            cv2.fillPoly(grid, [self._px(ring)], 0, lineType=cv2.LINE_8, shift=RASTER_SHIFT)
        self._raster_rects(grid, self.rect_poses, self.rect_dims)
        self.grid = grid
        free = (grid == 0).astype(np.uint8)
        self.edt = cv2.distanceTransform(free, cv2.DIST_L2, cv2.DIST_MASK_PRECISE).astype(np.float32) * self.res
        depth = cv2.distanceTransform(grid, cv2.DIST_L2, cv2.DIST_MASK_PRECISE).astype(np.float32) * self.res
        self.depth = np.minimum(depth, np.float32(self.depth_cap))
        # signed field: distance to obstacles outside them, minus the depth inside them (capped: only whether a
        # point lies deeper than sure_depth is ever asked)
        self._sdf_flat = (self.edt - self.depth).ravel()

    def _grid_frame(self) -> None:
        """The grid's origin, cell, shape and the raster's growth and slack (the lot's alone)."""
        res = self.settings.grid_resolution
        xmin, ymin, xmax, ymax = self.lot.bounds()
        pad = 2 * res
        self.origin = np.array([xmin - pad, ymin - pad])
        self.res = res
        w = int(math.ceil((xmax - xmin + 2 * pad) / res))
        h = int(math.ceil((ymax - ymin + 2 * pad) / res))
        self.shape = (h, w)
        half_diag = res * math.sqrt(0.5)
        self.grow = 2.0 * half_diag  # every cell that contains an obstacle point lies well inside the grown shape
        self.slack = 2.0 * half_diag + 1e-6
        # a point deeper than this inside the raster lies inside a true obstacle
        self.sure_depth = self.grow + 2.0 * half_diag + 1e-6
        self.depth_cap = self.sure_depth + 2.0 * res

    def _px(self, pts: np.ndarray) -> np.ndarray:
        u = (pts - self.origin) / self.res - 0.5  # pixel-centre coordinates
        return np.round(u * float(1 << RASTER_SHIFT)).astype(np.int32)

    def _grown_px(self, poses: np.ndarray, dims: np.ndarray) -> list[np.ndarray]:
        """The rectangles grown by ``grow``, as the rasteriser's vertices (one (4, 2) array each)."""
        g = self.grow
        return [self._px(c) for c in rect_corners(poses, dims[:, 0] + 2 * g, dims[:, 1] + 2 * g)] if len(poses) else []

    def _raster_rects(self, grid: np.ndarray, poses: np.ndarray, dims: np.ndarray) -> list[np.ndarray]:
        """Marks the rectangles, grown by ``grow``, occupied in ``grid``; returns their vertices (:meth:`_grown_px`)."""
        polygons = self._grown_px(poses, dims)
        for pts in polygons:  # one call each: fillPoly fills several contours even-odd (overlaps would be holes)
            cv2.fillPoly(grid, [pts], 1, lineType=cv2.LINE_8, shift=RASTER_SHIFT)
        return polygons

    @functools.cached_property
    def edt_max(self) -> float:
        """The largest distance of the distance field (m): no obstacle added to this world is nearer than that to
        a cell it leaves unchanged (:mod:`avp_collision.world_extend`)."""
        return float(self.edt.max())

    def clearance(self, xy: np.ndarray) -> np.ndarray:
        """Lower bound on the distance (m) from points (..., 2) to the static obstacles (0 off the grid)."""
        xy = np.asarray(xy, dtype=float)
        return self._clearance_xy(xy[..., 0], xy[..., 1])

    def _clearance_xy(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.maximum(self._sdf_xy(x, y) - self.slack, 0.0)

    def _sdf_xy(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Raw signed field at points (off the grid: -inf, i.e. certainly outside L)."""
        j = ((x - self.origin[0]) * (1.0 / self.res)).astype(np.int64)  # >= 0 on the grid (padded)
        i = ((y - self.origin[1]) * (1.0 / self.res)).astype(np.int64)
        h, w = self.shape
        ok = (x >= self.origin[0]) & (y >= self.origin[1]) & (i < h) & (j < w)
        if ok.all():
            return self._sdf_flat[i * w + j]
        out = np.full(np.shape(x), -np.inf, dtype=np.float32)
        out[ok] = self._sdf_flat[i[ok] * w + j[ok]]
        return out

    def disc_centres(self, poses: np.ndarray) -> np.ndarray:
        """(N, n_discs, 2) centres of the covering discs."""
        p = np.asarray(poses, dtype=float).reshape(-1, 3)
        c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
        off = self.disc_offsets
        return np.stack([p[:, 0, None] + c[:, None] * off, p[:, 1, None] + s[:, None] * off], axis=-1)

    def footprint_clearance(self, poses: np.ndarray) -> np.ndarray:
        """Approximate (lower-bound) clearance of each footprint: min over discs of clearance - disc radius."""
        return self.clearance(self.disc_centres(poses)).min(axis=1) - self.disc_radius

    # ------------------------------------------------------------------ checks
    def _rect_hits(self, x, y, c, s, margin: float) -> np.ndarray:
        """Exact: (N,) True where the footprint comes within ``margin`` (SAT sense) of an obstacle rectangle."""
        hit = np.zeros(len(x), dtype=bool)
        if not len(self.rect_poses) or not len(x):
            return hit
        dx = self.rect_poses[None, :, 0] - x[:, None]
        dy = self.rect_poses[None, :, 1] - y[:, None]
        reach = self.circum + self.rect_circum[None, :] + (margin[:, None] if np.ndim(margin) else margin)
        ii, jj = np.nonzero(dx * dx + dy * dy <= reach * reach)
        if not len(ii):
            return hit
        if np.ndim(margin):
            margin = margin[ii]
        tx, ty = dx[ii, jj], dy[ii, jj]
        c, s = c[ii], s[ii]
        oc, os_ = self.rect_cos[jj], self.rect_sin[jj]
        bl, bw = self.rect_half[jj, 0], self.rect_half[jj, 1]
        al, aw = self.half_l, self.half_w
        cd = np.abs(c * oc + s * os_)
        sd = np.abs(s * oc - c * os_)
        sep = (
            (np.abs(tx * c + ty * s) > al + bl * cd + bw * sd + margin)
            | (np.abs(-tx * s + ty * c) > aw + bl * sd + bw * cd + margin)
            | (np.abs(tx * oc + ty * os_) > bl + al * cd + aw * sd + margin)
            | (np.abs(-tx * os_ + ty * oc) > bw + al * sd + aw * cd + margin)
        )
        hit[ii[~sep]] = True
        return hit

    def _inside_lot(self, x, y, c, s, margin: float) -> np.ndarray:
        b = self.boundary
        if b.convex:  # support function of the rectangle along each inward normal
            nx, ny = b.normals[:, 0], b.normals[:, 1]
            centre = x[:, None] * nx + y[:, None] * ny - b.offsets
            ext = self.half_l * np.abs(c[:, None] * nx + s[:, None] * ny) + self.half_w * np.abs(
                -s[:, None] * nx + c[:, None] * ny)
            return (centre - ext >= (margin[:, None] if np.ndim(margin) else margin)).all(axis=1)
        poses = np.stack([x, y, np.arctan2(s, c)], axis=1)
        corners = rect_corners(poses, self.length, self.width)
        if not np.ndim(margin):
            return b.inside(corners, margin)
        out = np.zeros(len(x), dtype=bool)
        for m in np.unique(margin):
            sel = margin == m
            out[sel] = b.inside(corners[sel], float(m))
        return out

    def exact_free_xyc(self, x, y, c, s, margin: float) -> np.ndarray:
        inside = self._inside_lot(x, y, c, s, margin)
        return inside & ~self._rect_hits(x, y, c, s, margin)

    def free_xyc(self, x: np.ndarray, y: np.ndarray, c: np.ndarray, s: np.ndarray, margin) -> np.ndarray:
        """:meth:`free` for poses given as centre coordinates and heading cosine/sine (1-D arrays).

        ``margin`` is a scalar or one value per pose.
        """
        off = self.disc_offsets
        sdf = self._sdf_xy(x[:, None] + c[:, None] * off, y[:, None] + s[:, None] * off).min(axis=1)
        out = sdf > self.disc_radius + margin + self.slack
        unsure = np.nonzero(~out & (sdf >= -self.sure_depth))[0]
        if len(unsure):
            m = margin[unsure] if np.ndim(margin) else margin
            out[unsure] = self.exact_free_xyc(x[unsure], y[unsure], c[unsure], s[unsure], m)
        return out

    def rect_collisions(self, poses: np.ndarray, margin: float) -> np.ndarray:
        """Exact: (N,) True where the footprint comes within ``margin`` (SAT sense) of an obstacle rectangle."""
        p = np.asarray(poses, dtype=float).reshape(-1, 3)
        return self._rect_hits(p[:, 0], p[:, 1], np.cos(p[:, 2]), np.sin(p[:, 2]), margin)

    def exact_free(self, poses: np.ndarray, margin: float) -> np.ndarray:
        """Exact test of every pose: (N,) True where free with ``margin``."""
        p = np.asarray(poses, dtype=float).reshape(-1, 3)
        return self.exact_free_xyc(p[:, 0], p[:, 1], np.cos(p[:, 2]), np.sin(p[:, 2]), margin)

    def free(self, poses: np.ndarray, margin: float) -> np.ndarray:
        """(N,) True where the footprint at each pose is free with ``margin`` (disc pre-check, then exact).

        Non-finite poses are reported as not free.
        """
        p = np.asarray(poses, dtype=float).reshape(-1, 3)
        fin = np.isfinite(p).all(axis=1)
        if not fin.all():
            out = np.zeros(len(p), dtype=bool)
            out[fin] = self.free(p[fin], margin)
            return out
        return self.free_xyc(p[:, 0], p[:, 1], np.cos(p[:, 2]), np.sin(p[:, 2]), margin)

    def all_free(self, poses: np.ndarray, margin: float) -> bool:
        return bool(self.free(poses, margin).all())

"""The Hybrid A* heuristic (paper §V-D, after Nawaz et al. and Dolgov et al.), ROS-free.

h(pose) = max(Reeds-Shepp length from the pose to the ego ignoring obstacles, obstacle-aware 2-D distance from
the pose to the ego). The Reeds-Shepp part reads a look-up table over the relative pose (:func:`rs_length_table`,
built once per process); the 2-D part is an 8-connected Dijkstra on a ``heuristic_resolution`` grid, built once
per decision step and shared by every candidate goal (:class:`EgoHeuristic`).
"""

from __future__ import annotations

import functools
import math
import sys

import cv2
import numpy as np

from avp_collision.static import StaticWorld
from avp_search.paths import wrap
from avp_search.settings import SearchConfig
from avp_search.table_cache import cached_table
from avp_world import reeds_shepp
from avp_world.reeds_shepp import reeds_shepp_batch

BIG = 1e9  # "unreachable" distance
DISTANCE_CACHE_SIZE = 64  # 2-D distance maps a cache keeps (one per static world and start cell)


@functools.lru_cache(maxsize=8)
def rs_length_table(radius: float, res: float, extent: float, bins: int) -> np.ndarray:
    """Reeds-Shepp lengths from the origin (heading 0) to (x, y, φ) for x, y in [0, extent] step ``res`` and φ
    at the centres of ``bins`` heading bins; (nx, ny, bins) float32. Other quadrants follow by symmetry. Built once
    per process, and kept on disk for the next (:mod:`avp_search.table_cache`)."""
    xs = np.arange(0.0, extent + 1e-9, res)
    th = -math.pi + 2.0 * math.pi * (np.arange(bins) + 0.5) / bins

    def build() -> np.ndarray:
        gx, gy, gt = np.meshgrid(xs, xs, th, indexing="ij")
        goals = np.stack([gx.ravel(), gy.ravel(), gt.ravel()], axis=1)
        out = np.empty(len(goals))
        for i in range(0, len(goals), 8192):
            out[i:i + 8192] = reeds_shepp_batch(np.zeros(3), goals[i:i + 8192], radius).length
        return out.reshape(gx.shape).astype(np.float32)

    table = cached_table("rs_length_table", (radius, res, extent, bins), (sys.modules[__name__], reeds_shepp),
                         (len(xs), len(xs), bins), build)
    table.flags.writeable = False
    return table


def coarse_max(world: StaticWorld, k: int) -> np.ndarray:
    """The largest clearance (``world.edt``) in each k x k block of cells (the grid padded with 0), kept on the world:
    the heuristics rooted in one world share it."""
    memo = world.__dict__.setdefault("_coarse_max", {})
    if k not in memo:
        edt = world.edt
        h, w = edt.shape
        hh, ww = -(-h // k), -(-w // k)
        pad = np.zeros((hh * k, ww * k), dtype=np.float32)
        pad[:h, :w] = edt
        rows = pad.reshape(hh, k, ww * k)
        m = rows[:, 0].copy()
        for i in range(1, k):  # row by row, then within each block: the same maxima, far faster than one reduce
            np.maximum(m, rows[:, i], out=m)
        memo[k] = m.reshape(hh, ww, k).max(axis=2)
    return memo[k]


class EgoHeuristic:
    """h(pose) = max(RS length pose -> ego, 2-D obstacle-aware distance pose -> ego); built once per step."""

    def __init__(self, world: StaticWorld, ego: np.ndarray, settings: SearchConfig, cache: dict | None = None):
        s = settings.search
        self.ego = np.asarray(ego, dtype=float)
        self.radius = settings.plan_radius
        self.table = rs_length_table(round(self.radius, 9), s.rs_table_resolution, s.rs_table_extent, s.heading_bins)
        self.t_res = s.rs_table_resolution
        self.t_n = self.table.shape[0]
        self.bins = s.heading_bins
        self._distance_map(world, s.heuristic_resolution, cache)

    def _distance_map(self, world: StaticWorld, res: float, cache: dict | None) -> None:
        """Distances (m) from the ego's cell over cells that may hold the car centre (8-connected).

        The map depends only on the static world and the start cell, so with a ``cache`` (keyed by
        ``world.key``, which the owner of the world sets) a caller rooting many heuristics in the same world (the
        Hybrid A* predictor: one per vehicle and step) computes it once per cell; and as it depends on the world only
        through the coarse cells that may hold the car centre, a new world with the same such cells finds the map of
        an earlier one (the same map, computed once); at most :data:`DISTANCE_CACHE_SIZE` maps are kept."""
        k = max(1, int(round(res / world.res)))
        self.h_res = k * world.res
        self.h_origin = world.origin
        si = int((self.ego[1] - world.origin[1]) // self.h_res)
        sj = int((self.ego[0] - world.origin[0]) // self.h_res)
        key = (world.key, res, (si, sj))
        if cache is not None and key in cache:
            self.reachable, self.dist = cache[key]
            return
        best = coarse_max(world, k)
        hh, ww = best.shape
        # a coarse cell is free if some point of it may hold the car centre (clearance >= half width, less the
        # grid's conservative slack and the rasterisation growth)
        free = best >= max(world.half_w - 2.0 * world.slack, 0.05)
        inside = 0 <= si < hh and 0 <= sj < ww
        if inside:
            free[si, sj] = True
        # the map depends only on the coarse free cells and the start: a world that differs only within cells
        # (a standing pedestrian's box a few centimetres on, a parked car's held pose renewed) has the same map
        free_key = ("free", self.h_res, world.origin.tobytes(), (si, sj), free.shape, free.tobytes())
        if cache is not None and free_key in cache:
            self.reachable, self.dist = cache[key] = cache[free_key]
            return
        dist = np.full((hh, ww), BIG, dtype=np.float32)
        if inside:
            dist[si, sj] = 0.0
        blocked = ~free
        cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
        box = np.ones((3, 3), np.uint8)
        step, diag = np.float32(self.h_res), np.float32(self.h_res * math.sqrt(2.0))
        for it in range(4 * (hh + ww)):
            new = np.minimum(np.minimum(dist, cv2.erode(dist, cross) + step), cv2.erode(dist, box) + diag)
            new[blocked] = BIG
            if it % 4 == 3 and np.array_equal(new, dist):
                break
            dist = new
        self.reachable = dist < BIG / 2
        # blocked cells next to free ones get their neighbour's value + one step (poses near walls)
        filled = dist.copy()
        for _ in range(2):
            filled = np.where(blocked, np.minimum(filled, cv2.erode(filled, box) + diag), filled)
        self.dist = filled
        if cache is not None:
            if len(cache) >= 2 * DISTANCE_CACHE_SIZE:
                cache.clear()
            cache[key] = cache[free_key] = (self.reachable, self.dist)

    def dist2d(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=float)
        i = np.floor((xy[..., 1] - self.h_origin[1]) / self.h_res).astype(np.int64)
        j = np.floor((xy[..., 0] - self.h_origin[0]) / self.h_res).astype(np.int64)
        ok = (i >= 0) & (i < self.dist.shape[0]) & (j >= 0) & (j < self.dist.shape[1])
        out = np.full(xy.shape[:-1], BIG)
        out[ok] = self.dist[i[ok], j[ok]]
        return out

    def reachable_at(self, xy: np.ndarray) -> bool:
        return bool(self.dist2d(np.asarray(xy, dtype=float)[None, :2])[0] < BIG / 2)

    def rs(self, poses: np.ndarray) -> np.ndarray:
        """Reeds-Shepp length (table, nearest cell; Euclidean beyond the table) from each pose to the ego."""
        p = np.asarray(poses, dtype=float).reshape(-1, 3)
        dx, dy = self.ego[0] - p[:, 0], self.ego[1] - p[:, 1]
        c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
        x, y = c * dx + s * dy, -s * dx + c * dy
        phi = wrap(self.ego[2] - p[:, 2]) * np.where(x < 0, -1.0, 1.0) * np.where(y < 0, -1.0, 1.0)
        ix = np.rint(np.abs(x) / self.t_res).astype(np.int64)
        iy = np.rint(np.abs(y) / self.t_res).astype(np.int64)
        ib = np.floor((phi + math.pi) / (2.0 * math.pi) * self.bins).astype(np.int64) % self.bins
        inside = (ix < self.t_n) & (iy < self.t_n)
        out = np.hypot(x, y)
        out[inside] = self.table[ix[inside], iy[inside], ib[inside]]
        return out

    def __call__(self, poses: np.ndarray) -> np.ndarray:
        return self.both(poses)[0]

    def both(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(h, 2-D distance) of each pose."""
        p = np.asarray(poses, dtype=float).reshape(-1, 3)
        d = self.dist2d(p[:, :2])
        return np.maximum(self.rs(p), d), d

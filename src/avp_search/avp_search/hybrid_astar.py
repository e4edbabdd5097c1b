"""Hybrid A* for the ego (paper §V-D: "we use the Hybrid A* implementation from [Nawaz]"), ROS-free.

Search space (x, y, θ), closed set on a (``xy_resolution``, ``heading_bins``) grid. Motion primitives are
arcs of length ``primitive_length`` with curvature ``f * kappa_plan`` for f in ``steering_fractions`` (kappa_plan
= 1 / R_plan, R_plan = ``curvature_reserve`` * R_min, so every path respects |ω| <= |v| / R_min with 10 %
to spare for the tracker), driven forward and in reverse. All primitives of a node are generated, sampled
every ``sample_step`` and collision-checked in one numpy call.

**Direction of search.** The search runs *from the goal poses back to the ego* (the car model is
reversible: driving an arc backwards retraces it, so an edge searched with direction d is driven with
direction -d). This has two advantages for parking: (1) the hard part, threading the car into the slot,
is done by the primitives leaving the slot and the analytic Reeds-Shepp shot ends in the open aisle where
the ego is, and (2) the heuristic depends only on the ego pose, so it is computed once per decision step
and shared by all candidate goals (:class:`EgoHeuristic`). Both headings of a spot (spot heading and +π)
are seeds of one search.

**Cost** g (driving order): length, + ``reverse_penalty`` per metre reversed, + ``steer_penalty`` * |f| per
metre, + ``steer_change_penalty`` * |Δf| per change of curvature, + ``switch_penalty`` per cusp.

**Heuristic** h = max(Reeds-Shepp length to the ego ignoring obstacles (look-up table over the relative
pose, built once per process), obstacle-aware 2-D distance to the ego (8-connected Dijkstra on a
``heuristic_resolution`` grid, computed once per decision step)); f = g + ``heuristic_weight`` * h.

**Analytic expansion**: a shortest Reeds-Shepp path (cusps charged ``switch_penalty``) from the popped node
to the ego, tried on every pop with h < ``analytic_near`` and every ``analytic_every`` pops otherwise; it
ends the search when collision-free (samples within ``start_relax_distance`` of the ego are checked with the
smaller ``verify_margin``, since the ego already stands there).

Failures return a :class:`PlanResult` with ``success = False`` and a reason: "invalid input: NaN",
"start in collision", "goal in collision", "goal unreachable (2-D)", "goal beyond the length limit",
"no path within N iterations", "time cap (T s)", "no path within the length limit", "search space exhausted".
"""

from __future__ import annotations

import functools
import heapq
import math
import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from avp_search.collision import StaticWorld
from avp_search.paths import Path, arc_poses, merge_segments, sample_xycs, wrap
from avp_search.rs_scalar import CURVATURE_SIGN, rs_candidates
from avp_search.settings import SearchConfig
from avp_world.reeds_shepp import reeds_shepp_batch

_BIG = 1e9
BATCH_F_SLACK = 1.0  # only open nodes whose f is within this of the best one share an expansion batch


# -------------------------------------------------------------------------------------------- heuristics


@functools.lru_cache(maxsize=8)
def rs_length_table(radius: float, res: float, extent: float, bins: int) -> np.ndarray:
    """Reeds-Shepp lengths from the origin (heading 0) to (x, y, φ) for x, y in [0, extent] step ``res`` and φ
    at the centres of ``bins`` heading bins; (nx, ny, bins) float32. Other quadrants follow by symmetry."""
    xs = np.arange(0.0, extent + 1e-9, res)
    th = -math.pi + 2.0 * math.pi * (np.arange(bins) + 0.5) / bins
    gx, gy, gt = np.meshgrid(xs, xs, th, indexing="ij")
    goals = np.stack([gx.ravel(), gy.ravel(), gt.ravel()], axis=1)
    out = np.empty(len(goals))
    for i in range(0, len(goals), 8192):
        out[i:i + 8192] = reeds_shepp_batch(np.zeros(3), goals[i:i + 8192], radius).length
    table = out.reshape(gx.shape).astype(np.float32)
    table.flags.writeable = False
    return table


class EgoHeuristic:
    """h(pose) = max(RS length pose -> ego, 2-D obstacle-aware distance pose -> ego); built once per step."""

    def __init__(self, world: StaticWorld, ego: np.ndarray, settings: SearchConfig):
        s = settings.search
        self.ego = np.asarray(ego, dtype=float)
        self.radius = settings.plan_radius
        self.table = rs_length_table(round(self.radius, 9), s.rs_table_resolution, s.rs_table_extent, s.heading_bins)
        self.t_res = s.rs_table_resolution
        self.t_n = self.table.shape[0]
        self.bins = s.heading_bins
        self._dijkstra(world, s.heuristic_resolution)

    def _dijkstra(self, world: StaticWorld, res: float) -> None:
        """Distances (m) from the ego's cell over cells that may hold the car centre (8-connected)."""
        k = max(1, int(round(res / world.res)))
        self.h_res = k * world.res
        edt = world.edt
        h, w = edt.shape
        hh, ww = -(-h // k), -(-w // k)
        pad = np.zeros((hh * k, ww * k), dtype=np.float32)
        pad[:h, :w] = edt
        # a coarse cell is free if some point of it may hold the car centre (clearance >= half width, less the
        # grid's conservative slack and the rasterisation growth)
        best = pad.reshape(hh, k, ww, k).max(axis=(1, 3))
        free = best >= max(world.half_w - 2.0 * world.slack, 0.05)
        self.h_origin = world.origin
        si = int((self.ego[1] - world.origin[1]) // self.h_res)
        sj = int((self.ego[0] - world.origin[0]) // self.h_res)
        dist = np.full((hh, ww), _BIG, dtype=np.float32)
        if 0 <= si < hh and 0 <= sj < ww:
            free[si, sj] = True
            dist[si, sj] = 0.0
        blocked = ~free
        cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
        box = np.ones((3, 3), np.uint8)
        step, diag = np.float32(self.h_res), np.float32(self.h_res * math.sqrt(2.0))
        for it in range(4 * (hh + ww)):
            new = np.minimum(np.minimum(dist, cv2.erode(dist, cross) + step), cv2.erode(dist, box) + diag)
            new[blocked] = _BIG
            if it % 4 == 3 and np.array_equal(new, dist):
                break
            dist = new
        self.reachable = dist < _BIG / 2
        # blocked cells next to free ones get their neighbour's value + one step (poses near walls)
        filled = dist.copy()
        for _ in range(2):
            filled = np.where(blocked, np.minimum(filled, cv2.erode(filled, box) + diag), filled)
        self.dist = filled

    def dist2d(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=float)
        i = np.floor((xy[..., 1] - self.h_origin[1]) / self.h_res).astype(np.int64)
        j = np.floor((xy[..., 0] - self.h_origin[0]) / self.h_res).astype(np.int64)
        ok = (i >= 0) & (i < self.dist.shape[0]) & (j >= 0) & (j < self.dist.shape[1])
        out = np.full(xy.shape[:-1], _BIG)
        out[ok] = self.dist[i[ok], j[ok]]
        return out

    def reachable_at(self, xy: np.ndarray) -> bool:
        return bool(self.dist2d(np.asarray(xy, dtype=float)[None, :2])[0] < _BIG / 2)

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


# ------------------------------------------------------------------------------------------------ search


@dataclass
class PlanResult:
    """Outcome of one Hybrid A* query.

    path: from the ego pose to the reached goal, in driving order (None on failure); goal_index: which of the
    goal poses was reached; cost: search cost g of the path; stats: iterations, expansions, analytic
    attempts, nodes, time_s.
    """

    success: bool
    reason: str = ""
    path: Path | None = None
    goal: np.ndarray | None = None
    goal_index: int = -1
    cost: float = math.inf
    stats: dict = field(default_factory=dict)

    def sampled(self, step: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
        """(poses (K, 3), directions (K,): +1 forward / -1 reverse) sampled every <= ``step`` m along the path."""
        if self.path is None:
            return np.zeros((0, 3)), np.zeros(0, dtype=int)
        poses, dirs, _, _ = self.path.sample(step)
        return poses, dirs

    @property
    def poses(self) -> np.ndarray:
        """(K, 3) poses every <= 0.1 m along the path (empty on failure)."""
        return self.sampled(0.1)[0]

    @property
    def directions(self) -> np.ndarray:
        """(K,) driving direction of the segment ending at each of :attr:`poses`."""
        return self.sampled(0.1)[1]


class HybridAStar:
    """Hybrid A* queries towards one ego pose in one static world (see the module docstring).

    Args:
        world: the static world of this decision step.
        ego: (3,) current ego pose (the start of every returned path).
        settings: planner settings.
        heuristic: a shared :class:`EgoHeuristic` for ``ego`` (built if None).
    """

    def __init__(self, world: StaticWorld, ego: np.ndarray, settings: SearchConfig,
                 heuristic: EgoHeuristic | None = None):
        self.world = world
        self.settings = settings
        self.ego = np.asarray(ego, dtype=float)
        self._ego_ok = bool(np.isfinite(self.ego).all() and self.ego.shape == (3,))
        self.heuristic = heuristic
        s = settings.search
        self.radius = settings.plan_radius
        kap = 1.0 / self.radius
        fr = np.asarray(s.steering_fractions, dtype=float)
        self.prim_frac = np.concatenate([fr, fr])
        self.prim_kappa = self.prim_frac * kap
        self.prim_dir = np.concatenate([np.ones(len(fr)), -np.ones(len(fr))])  # search direction
        n = max(1, math.ceil(s.primitive_length / s.sample_step - 1e-9))
        self.n_samp = n
        sl = s.primitive_length * np.arange(1, n + 1) / n
        self.prim_local = np.stack(
            [arc_poses(0.0, 0.0, 0.0, k, d * sl) for k, d in zip(self.prim_kappa, self.prim_dir, strict=True)]
        )  # (P, n, 3)
        self.loc_x = self.prim_local[..., 0].ravel()
        self.loc_y = self.prim_local[..., 1].ravel()
        self.loc_c = np.cos(self.prim_local[..., 2]).ravel()
        self.loc_s = np.sin(self.prim_local[..., 2]).ravel()
        self.end_local = self.prim_local[:, -1, :]
        # driving cost of each primitive (actual direction = - search direction)
        rev = self.prim_dir > 0
        self.prim_cost = s.primitive_length * (1.0 + s.reverse_penalty * rev + s.steer_penalty * np.abs(self.prim_frac))
        self.bin_w = 2.0 * math.pi / s.heading_bins

    # ---------------------------------------------------------------------------------------------- utils
    def _key(self, x: float, y: float, th: float) -> tuple[int, int, int]:
        r = self.settings.search.xy_resolution
        return (math.floor(x / r), math.floor(y / r), int(((th + math.pi) % (2 * math.pi)) // self.bin_w))

    def _want_shot(self, h: float, d2: float, x: float, y: float, it: int) -> bool:
        """Try a Reeds-Shepp shot on every pop near the ego and every ``analytic_every`` pops otherwise, but
        never when the 2-D obstacle-aware distance shows obstacles in the way (much longer than the line)."""
        s = self.settings.search
        euclid = math.hypot(x - self.ego[0], y - self.ego[1])
        if d2 > s.analytic_detour * euclid + 2.0 * self.heuristic.h_res:
            return False
        return h < s.analytic_near or it % s.analytic_every == 1

    def _shot_free(self, segs: tuple[tuple[float, float], ...], start: tuple[float, float, float]) -> bool:
        """Collision check of a Reeds-Shepp shot from a node to the ego (driving order reversed)."""
        c = self.settings.collision
        x, y, cs, sn, arc = sample_xycs(start, segs, self.settings.search.sample_step)
        margin = np.where(arc[-1] - arc < c.start_relax_distance, c.verify_margin, c.footprint_margin)
        return bool(self.world.free_xyc(x, y, cs, sn, margin).all())

    # ---------------------------------------------------------------------------------------------- query
    def plan(self, goals: np.ndarray, max_iterations: int | None = None, time_cap: float | None = None,
             max_length: float | None = None) -> PlanResult:
        """Search a path from the ego to any of ``goals`` (G, 3), optionally no longer than ``max_length`` m
        (branches that cannot stay within it by the 2-D lower bound are pruned)."""
        t0 = time.perf_counter()
        s, c = self.settings.search, self.settings.collision
        max_it = s.max_iterations if max_iterations is None else int(max_iterations)
        cap = s.time_cap if time_cap is None else float(time_cap)
        goals = np.asarray(goals, dtype=float).reshape(-1, 3)
        stats = {"iterations": 0, "expansions": 0, "analytic": 0, "nodes": 0, "time_s": 0.0}

        def fail(reason: str) -> PlanResult:
            stats["time_s"] = time.perf_counter() - t0
            return PlanResult(False, reason, stats=stats)

        if not self._ego_ok or not np.isfinite(goals).all() or not len(goals):
            return fail("invalid input: NaN" if len(goals) else "invalid input: no goal")
        world = self.world
        if not world.exact_free(self.ego[None], 0.0)[0]:
            return fail("start in collision")
        gfree = world.free(goals, c.footprint_margin)
        if not gfree.any():
            return fail("goal in collision")
        if self.heuristic is None:  # built once per ego pose and world, not counted against the time cap
            t_h = time.perf_counter()
            self.heuristic = EgoHeuristic(world, self.ego, self.settings)
            t0 += time.perf_counter() - t_h
        heur = self.heuristic
        if not any(heur.reachable_at(g) for g in goals[gfree]):
            return fail("goal unreachable (2-D)")
        lmax = math.inf if max_length is None else float(max_length)
        slack2d = math.sqrt(2.0) * heur.h_res
        if lmax < math.inf and float(np.min(heur.dist2d(goals[gfree, :2]))) / 1.0824 - slack2d > lmax:
            return fail("goal beyond the length limit")
        pruned = False

        ego_t = (float(self.ego[0]), float(self.ego[1]), float(self.ego[2]))
        w = s.heuristic_weight
        # node arrays
        nx: list[float] = []
        ny: list[float] = []
        nth: list[float] = []
        ng: list[float] = []
        nh: list[float] = []
        nd: list[float] = []  # 2-D obstacle-aware distance to the ego
        nl: list[float] = []  # path length from the goal
        npar: list[int] = []
        nprim: list[int] = []
        ndir: list[float] = []  # actual driving direction of the edge into the node (0: seed)
        heap: list[tuple[float, int]] = []
        best_g: dict[tuple[int, int, int], float] = {}
        closed: set[tuple[int, int, int]] = set()
        hg, dg = heur.both(goals)
        for gi in np.nonzero(gfree)[0]:
            gx, gy, gt = (float(v) for v in goals[gi])
            nx.append(gx)
            ny.append(gy)
            nth.append(gt)
            ng.append(0.0)
            nh.append(float(hg[gi]))
            nd.append(float(dg[gi]))
            nl.append(0.0)
            npar.append(-int(gi) - 1)  # seeds store -(goal index) - 1
            nprim.append(-1)
            ndir.append(0.0)
            best_g[self._key(gx, gy, gt)] = 0.0
            heapq.heappush(heap, (w * float(hg[gi]), len(nx) - 1))

        n_prim, n_samp = self.prim_local.shape[0], self.prim_local.shape[1]
        lx, ly, lc, ls = self.loc_x, self.loc_y, self.loc_c, self.loc_s
        el = self.end_local
        batch_size = max(1, s.batch_size)
        while heap:
            # pop up to batch_size open nodes; each may end the search with a Reeds-Shepp shot
            batch: list[int] = []
            f_first = math.inf
            while heap and len(batch) < batch_size:
                if stats["iterations"] >= max_it:
                    return fail(f"no path within {max_it} iterations")
                if time.perf_counter() - t0 > cap:
                    return fail(f"time cap ({cap:.3f} s)")
                if batch and heap[0][0] > f_first + BATCH_F_SLACK:
                    break  # only nodes (nearly) as good as the best one share a batch
                f_top, nid = heapq.heappop(heap)
                x, y, th = nx[nid], ny[nid], nth[nid]
                key = self._key(x, y, th)
                if key in closed or ng[nid] > best_g.get(key, math.inf) + 1e-9:
                    continue
                closed.add(key)
                stats["iterations"] += 1
                f_first = min(f_first, f_top)
                if self._want_shot(nh[nid], nd[nid], x, y, stats["iterations"]):
                    stats["analytic"] += 1
                    for _, rs in rs_candidates((x, y, th), ego_t, self.radius, s.switch_penalty, s.analytic_candidates,
                                               s.analytic_slack):
                        segs = tuple((CURVATURE_SIGN[k] / self.radius, ln) for k, ln in rs)
                        if nl[nid] + sum(abs(ln) for _, ln in segs) > lmax:
                            pruned = True
                            continue
                        if self._shot_free(segs, (x, y, th)):
                            return self._finish(nid, segs, nx, ny, nth, ng, npar, nprim, ndir, goals, stats, t0)
                batch.append(nid)
            if not batch:
                break
            # expansion of the whole batch: all primitives of all nodes in one call
            stats["expansions"] += len(batch)
            bx = np.array([nx[i] for i in batch])
            by = np.array([ny[i] for i in batch])
            bt = np.array([nth[i] for i in batch])
            cs, sn = np.cos(bt)[:, None], np.sin(bt)[:, None]
            ok = world.free_xyc(
                (bx[:, None] + cs * lx - sn * ly).ravel(), (by[:, None] + sn * lx + cs * ly).ravel(),
                (cs * lc - sn * ls).ravel(), (sn * lc + cs * ls).ravel(), c.footprint_margin,
            ).reshape(len(batch), n_prim, n_samp).all(axis=2)
            bi, pi = np.nonzero(ok)
            if not len(bi):
                continue
            cb, sb = cs[bi, 0], sn[bi, 0]
            ends = np.stack([bx[bi] + cb * el[pi, 0] - sb * el[pi, 1], by[bi] + sb * el[pi, 0] + cb * el[pi, 1],
                             wrap(bt[bi] + el[pi, 2])], axis=1)
            hs, ds = heur.both(ends)
            for m in range(len(bi)):
                if hs[m] >= _BIG / 2:
                    continue
                ex, ey, et = float(ends[m, 0]), float(ends[m, 1]), float(ends[m, 2])
                k2 = self._key(ex, ey, et)
                if k2 in closed:
                    continue
                nid = batch[bi[m]]
                p = int(pi[m])
                length = nl[nid] + s.primitive_length
                if length + float(ds[m]) / 1.0824 - slack2d > lmax:
                    pruned = True
                    continue
                adir = -self.prim_dir[p]
                cost = ng[nid] + self.prim_cost[p]
                pprim, pdir = nprim[nid], ndir[nid]
                if pprim >= 0:
                    cost += s.steer_change_penalty * abs(self.prim_frac[p] - self.prim_frac[pprim])
                if pdir != 0.0 and pdir != adir:
                    cost += s.switch_penalty
                if cost >= best_g.get(k2, math.inf) - 1e-9:
                    continue
                best_g[k2] = cost
                nx.append(ex)
                ny.append(ey)
                nth.append(et)
                ng.append(cost)
                nh.append(float(hs[m]))
                nd.append(float(ds[m]))
                nl.append(length)
                npar.append(nid)
                nprim.append(p)
                ndir.append(float(adir))
                heapq.heappush(heap, (cost + w * float(hs[m]), len(nx) - 1))
            stats["nodes"] = len(nx)
        return fail("no path within the length limit" if pruned else "search space exhausted")

    def _finish(self, nid, shot, nx, ny, nth, ng, npar, nprim, ndir, goals, stats, t0) -> PlanResult:
        s = self.settings.search
        # driving order: ego -> (reversed shot) -> node -> ... -> seed goal
        segs: list[tuple[float, float]] = [(k, -ln) for k, ln in reversed(shot)]
        m = nid
        while npar[m] >= 0:
            p = nprim[m]
            segs.append((float(self.prim_kappa[p]), float(-self.prim_dir[p] * s.primitive_length)))
            m = npar[m]
        gi = -npar[m] - 1
        path = Path((float(self.ego[0]), float(self.ego[1]), float(self.ego[2])), merge_segments(segs))
        shot_len = sum(abs(ln) for _, ln in shot)
        shot_rev = sum(abs(ln) for _, ln in shot if ln > 0)  # reversed in driving order
        cost = ng[nid] + shot_len + s.reverse_penalty * shot_rev + s.switch_penalty * Path((0, 0, 0), shot).n_switches
        stats["time_s"] = time.perf_counter() - t0
        stats["nodes"] = len(nx)
        return PlanResult(True, "", path=path, goal=goals[gi].copy(), goal_index=int(gi), cost=float(cost), stats=stats)

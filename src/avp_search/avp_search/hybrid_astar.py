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

import heapq
import math
import time
from dataclasses import dataclass, field

import numpy as np

from avp_collision.static import StaticWorld
from avp_search.heuristic import BIG, EgoHeuristic, rs_length_table
from avp_search.paths import Path, arc_poses, merge_segments, sample_xycs, wrap
from avp_search.rs_scalar import CURVATURE_SIGN, rs_candidates
from avp_search.settings import SearchConfig

__all__ = ["HybridAStar", "PlanResult", "EgoHeuristic", "rs_length_table", "BATCH_F_SLACK"]

BATCH_F_SLACK = 1.0  # only open nodes whose f is within this of the best one share an expansion batch


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
        s = self.settings.search
        q = _Query(goals=np.asarray(goals, dtype=float).reshape(-1, 3), t0=time.perf_counter(),
                   max_it=s.max_iterations if max_iterations is None else int(max_iterations),
                   cap=s.time_cap if time_cap is None else float(time_cap),
                   lmax=math.inf if max_length is None else float(max_length))
        reason = self._seed(q)
        if reason:
            return q.fail(reason)
        while q.heap:
            batch, result = self._pop_batch(q)
            if result is not None:
                return result
            if not batch:
                break
            self._expand(q, batch)
        return q.fail("no path within the length limit" if q.pruned else "search space exhausted")

    def _seed(self, q: _Query) -> str:
        """Check the query, build the heuristic if missing and push every collision-free goal as a seed; returns
        the failure reason ("" to go on)."""
        c, goals, world = self.settings.collision, q.goals, self.world
        if not self._ego_ok or not np.isfinite(goals).all() or not len(goals):
            return "invalid input: NaN" if len(goals) else "invalid input: no goal"
        if not world.exact_free(self.ego[None], 0.0)[0]:
            return "start in collision"
        gfree = world.free(goals, c.footprint_margin)
        if not gfree.any():
            return "goal in collision"
        if self.heuristic is None:  # built once per ego pose and world, not counted against the time cap
            t_h = time.perf_counter()
            self.heuristic = EgoHeuristic(world, self.ego, self.settings)
            q.t0 += time.perf_counter() - t_h
        heur = self.heuristic
        if not any(heur.reachable_at(g) for g in goals[gfree]):
            return "goal unreachable (2-D)"
        q.slack2d = math.sqrt(2.0) * heur.h_res
        if q.lmax < math.inf and float(np.min(heur.dist2d(goals[gfree, :2]))) / 1.0824 - q.slack2d > q.lmax:
            return "goal beyond the length limit"
        w = self.settings.search.heuristic_weight
        hg, dg = heur.both(goals)
        for gi in np.nonzero(gfree)[0]:
            gx, gy, gt = (float(v) for v in goals[gi])
            q.best_g[self._key(gx, gy, gt)] = 0.0
            q.add(gx, gy, gt, 0.0, float(hg[gi]), float(dg[gi]), 0.0, -int(gi) - 1, -1, 0.0,
                  w * float(hg[gi]))  # seeds store -(goal index) - 1 as parent
        return ""

    def _pop_batch(self, q: _Query) -> tuple[list[int], PlanResult | None]:
        """Pop up to ``batch_size`` open nodes (nearly) as good as the best one; each may end the search with a
        collision-free Reeds-Shepp shot to the ego. Returns (batch, the result if the search ended)."""
        s, stats = self.settings.search, q.stats
        ego_t = (float(self.ego[0]), float(self.ego[1]), float(self.ego[2]))
        batch: list[int] = []
        f_first = math.inf
        while q.heap and len(batch) < max(1, s.batch_size):
            if stats["iterations"] >= q.max_it:
                return batch, q.fail(f"no path within {q.max_it} iterations")
            if time.perf_counter() - q.t0 > q.cap:
                return batch, q.fail(f"time cap ({q.cap:.3f} s)")
            if batch and q.heap[0][0] > f_first + BATCH_F_SLACK:
                break  # only nodes (nearly) as good as the best one share a batch
            f_top, nid = heapq.heappop(q.heap)
            x, y, th = q.x[nid], q.y[nid], q.th[nid]
            key = self._key(x, y, th)
            if key in q.closed or q.g[nid] > q.best_g.get(key, math.inf) + 1e-9:
                continue
            q.closed.add(key)
            stats["iterations"] += 1
            f_first = min(f_first, f_top)
            if self._want_shot(q.h[nid], q.d[nid], x, y, stats["iterations"]):
                stats["analytic"] += 1
                for _, rs in rs_candidates((x, y, th), ego_t, self.radius, s.switch_penalty, s.analytic_candidates,
                                           s.analytic_slack):
                    segs = tuple((CURVATURE_SIGN[k] / self.radius, ln) for k, ln in rs)
                    if q.length[nid] + sum(abs(ln) for _, ln in segs) > q.lmax:
                        q.pruned = True
                        continue
                    if self._shot_free(segs, (x, y, th)):
                        return batch, self._finish(q, nid, segs)
            batch.append(nid)
        return batch, None

    def _expand(self, q: _Query, batch: list[int]) -> None:
        """Expand every node of ``batch`` by all primitives in one vectorised collision check; push the children
        that improve on their cell's best cost."""
        s, c = self.settings.search, self.settings.collision
        q.stats["expansions"] += len(batch)
        n_prim, n_samp = self.prim_local.shape[0], self.prim_local.shape[1]
        lx, ly, lc, ls, el = self.loc_x, self.loc_y, self.loc_c, self.loc_s, self.end_local
        bx = np.array([q.x[i] for i in batch])
        by = np.array([q.y[i] for i in batch])
        bt = np.array([q.th[i] for i in batch])
        cs, sn = np.cos(bt)[:, None], np.sin(bt)[:, None]
        ok = self.world.free_xyc(
            (bx[:, None] + cs * lx - sn * ly).ravel(), (by[:, None] + sn * lx + cs * ly).ravel(),
            (cs * lc - sn * ls).ravel(), (sn * lc + cs * ls).ravel(), c.footprint_margin,
        ).reshape(len(batch), n_prim, n_samp).all(axis=2)
        bi, pi = np.nonzero(ok)
        if not len(bi):
            return
        cb, sb = cs[bi, 0], sn[bi, 0]
        ends = np.stack([bx[bi] + cb * el[pi, 0] - sb * el[pi, 1], by[bi] + sb * el[pi, 0] + cb * el[pi, 1],
                         wrap(bt[bi] + el[pi, 2])], axis=1)
        hs, ds = self.heuristic.both(ends)
        w, closed, best_g = s.heuristic_weight, q.closed, q.best_g
        for m in range(len(bi)):
            if hs[m] >= BIG / 2:
                continue
            ex, ey, et = float(ends[m, 0]), float(ends[m, 1]), float(ends[m, 2])
            k2 = self._key(ex, ey, et)
            if k2 in closed:
                continue
            nid = batch[bi[m]]
            p = int(pi[m])
            length = q.length[nid] + s.primitive_length
            if length + float(ds[m]) / 1.0824 - q.slack2d > q.lmax:
                q.pruned = True
                continue
            adir = -self.prim_dir[p]
            cost = q.g[nid] + self.prim_cost[p]
            pprim, pdir = q.prim[nid], q.dir[nid]
            if pprim >= 0:
                cost += s.steer_change_penalty * abs(self.prim_frac[p] - self.prim_frac[pprim])
            if pdir != 0.0 and pdir != adir:
                cost += s.switch_penalty
            if cost >= best_g.get(k2, math.inf) - 1e-9:
                continue
            best_g[k2] = cost
            q.add(ex, ey, et, cost, float(hs[m]), float(ds[m]), length, nid, p, float(adir), cost + w * float(hs[m]))
        q.stats["nodes"] = len(q.x)

    def _finish(self, q: _Query, nid: int, shot: tuple[tuple[float, float], ...]) -> PlanResult:
        """The path of a search ended by a Reeds-Shepp shot from node ``nid`` to the ego."""
        s = self.settings.search
        # driving order: ego -> (reversed shot) -> node -> ... -> seed goal
        segs: list[tuple[float, float]] = [(k, -ln) for k, ln in reversed(shot)]
        m = nid
        while q.par[m] >= 0:
            p = q.prim[m]
            segs.append((float(self.prim_kappa[p]), float(-self.prim_dir[p] * s.primitive_length)))
            m = q.par[m]
        gi = -q.par[m] - 1
        path = Path((float(self.ego[0]), float(self.ego[1]), float(self.ego[2])), merge_segments(segs))
        shot_len = sum(abs(ln) for _, ln in shot)
        shot_rev = sum(abs(ln) for _, ln in shot if ln > 0)  # reversed in driving order
        cost = q.g[nid] + shot_len + s.reverse_penalty * shot_rev + s.switch_penalty * Path((0, 0, 0), shot).n_switches
        q.stats["time_s"] = time.perf_counter() - q.t0
        q.stats["nodes"] = len(q.x)
        return PlanResult(True, "", path=path, goal=q.goals[gi].copy(), goal_index=int(gi), cost=float(cost),
                          stats=q.stats)


@dataclass
class _Query:
    """State of one :meth:`HybridAStar.plan` call: node i's fields at index i of each list (pose, cost g,
    heuristic h, 2-D distance d to the ego, path length from the goal, parent, primitive, driving direction of
    the edge into it: 0 for a seed), the open heap of (f, node), the best g and the closed set by cell."""

    goals: np.ndarray
    t0: float
    max_it: int
    cap: float
    lmax: float
    slack2d: float = 0.0
    pruned: bool = False
    stats: dict = field(default_factory=lambda: {"iterations": 0, "expansions": 0, "analytic": 0, "nodes": 0,
                                                 "time_s": 0.0})
    x: list[float] = field(default_factory=list)
    y: list[float] = field(default_factory=list)
    th: list[float] = field(default_factory=list)
    g: list[float] = field(default_factory=list)
    h: list[float] = field(default_factory=list)
    d: list[float] = field(default_factory=list)
    length: list[float] = field(default_factory=list)
    par: list[int] = field(default_factory=list)
    prim: list[int] = field(default_factory=list)
    dir: list[float] = field(default_factory=list)
    heap: list[tuple[float, int]] = field(default_factory=list)
    best_g: dict[tuple[int, int, int], float] = field(default_factory=dict)
    closed: set[tuple[int, int, int]] = field(default_factory=set)

    def add(self, x: float, y: float, th: float, g: float, h: float, d: float, length: float, par: int, prim: int,
            direction: float, f: float) -> None:
        """Append a node and push it on the open heap with priority ``f``."""
        for column, value in ((self.x, x), (self.y, y), (self.th, th), (self.g, g), (self.h, h), (self.d, d),
                              (self.length, length), (self.par, par), (self.prim, prim), (self.dir, direction)):
            column.append(value)
        heapq.heappush(self.heap, (f, len(self.x) - 1))

    def fail(self, reason: str) -> PlanResult:
        self.stats["time_s"] = time.perf_counter() - self.t0
        return PlanResult(False, reason, stats=self.stats)

"""Collision checking against predicted agents that stop for the ego (``collision.reactive_steps``).

§V-C/§V-D check the ego's plan against each agent's predicted trajectory as if the agent went on whatever the ego
does. The agents of §III-B do not: agent A brakes at step t iff its next n_pass steps meet the ego's footprint
V_0,t. A planner that ignores this waits for agents that wait for it (Trautman & Krause, "Unfreezing the robot",
IROS 2010). Here each hypothesis is rolled out against the ego's plan with that rule, a look-ahead of L =
``reactive_steps`` steps (the ego does not know n_pass: L = the smallest n_pass is the cautious choice, an agent
that reacts late) and a reaction distance of the check's margin plus ``reactive_margin``:

    j_0 = -1 (the agent where it is; its first predicted pose stands for it),
    j_k = j_{k-1}            if one of its poses j_{k-1}+1 .. j_{k-1}+L comes within the reaction distance of the
                             ego's pose k-1 (it brakes),
          j_{k-1} + 1        otherwise (it follows its hypothesis; it holds its last pose after it, or leaves the
                             scene with ``hold_last`` off),

and the ego's pose k meets the agent if it comes within the margin of the agent's pose j_k. An agent on its way to
where the ego stands therefore stops short of it; the ego may not drive into an agent, standing or moving. Agents
that never come within reach of the plan are checked as before (j_k = k - 1), and so are agents outside
``dyn.veh_react`` / ``dyn.ped_react`` (the agents the planner has evidence of, ``collision.reactive_evidence``).

``collision.reactive_trigger`` (``dyn.react_trigger``) says what "within the reaction distance" is:

* ``margin`` (as shipped): the check's margin plus ``reactive_margin``. The agent is assumed to brake earlier than
  the simulator's does, which brakes only where its poses would overlap the ego: a car passing alongside the ego
  within the margin is assumed to stop, and does not (seed 184 of the busy lot).
* ``overlap``: ``reactive_margin`` alone (0: overlap, §III-B "meets"). The agent then comes up to the ego closer
  than the margin before it stops, so within the margin only the ego's own approach is a meeting: the ego's pose
  k meets the agent's pose j_k if they overlap, or if the gap is within the margin and smaller than from the ego's
  pose k - 1 to the same pose j_k.
"""

from __future__ import annotations

import numpy as np


def rect_gaps(e: np.ndarray, o: np.ndarray, al: float, aw: float, bl: np.ndarray, bw: np.ndarray) -> np.ndarray:
    """SAT separation of ego rectangles ``e`` (..., 3; half sizes al, aw) and agent rectangles ``o`` (..., 3; half
    sizes bl, bw, broadcast): the largest projected gap over the four axes (<= 0: they overlap)."""
    tx, ty = o[..., 0] - e[..., 0], o[..., 1] - e[..., 1]
    c, s = np.cos(e[..., 2]), np.sin(e[..., 2])
    oc, os_ = np.cos(o[..., 2]), np.sin(o[..., 2])
    cd = np.abs(c * oc + s * os_)
    sd = np.abs(s * oc - c * os_)
    return np.maximum.reduce([
        np.abs(tx * c + ty * s) - (al + bl * cd + bw * sd),
        np.abs(-tx * s + ty * c) - (aw + bl * sd + bw * cd),
        np.abs(tx * oc + ty * os_) - (bl + al * cd + aw * sd),
        np.abs(-tx * os_ + ty * oc) - (bw + al * sd + aw * cd),
    ])


def disc_gaps(e: np.ndarray, q: np.ndarray, al: float, aw: float, r: np.ndarray) -> np.ndarray:
    """Distance from ego rectangles ``e`` (..., 3) to discs at ``q`` (..., 2) of radius ``r`` (< 0: overlap)."""
    dx, dy = q[..., 0] - e[..., 0], q[..., 1] - e[..., 1]
    c, s = np.cos(e[..., 2]), np.sin(e[..., 2])
    lx = np.maximum(np.abs(dx * c + dy * s) - al, 0.0)
    ly = np.maximum(np.abs(-dx * s + dy * c) - aw, 0.0)
    return np.hypot(lx, ly) - r


def _gap_table(ego: np.ndarray, poses: np.ndarray, gaps_of, reach: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(agents near the plan, gaps G[a, j, k] of those agents' pose j to ego pose k; +inf where the centres are
    farther apart than ``reach``). Agents whose bounding box, grown by ``reach``, misses the plan's are left out
    before any pair is formed."""
    lo, hi = ego[:, :2].min(axis=0), ego[:, :2].max(axis=0)
    alo, ahi = poses[:, :, :2].min(axis=1), poses[:, :, :2].max(axis=1)
    cand = np.nonzero(((alo - reach[:, None] <= hi) & (ahi + reach[:, None] >= lo)).all(axis=1))[0]
    d = poses[cand, :, None, :2] - ego[None, None, :, :2]  # (A', H, n, 2)
    near = np.einsum("ahkd,ahkd->ahk", d, d) <= reach[cand, None, None] ** 2
    keep = near.any(axis=(1, 2))
    rows, near = cand[keep], near[keep]
    g = np.full((len(rows), poses.shape[1], len(ego)), np.inf)
    if len(rows):
        a, j, k = np.nonzero(near)
        g[a, j, k] = gaps_of(ego[k], rows[a], j)
    return rows, g


def _unique_rows(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct rows of ``x`` sorted lexicographically and, for each row, the index of its own:
    ``np.unique(x, axis=0, return_inverse=True)`` without its sort of a structured view (in a busy eight-ego
    episode it took 6 % of the CPU, this 3 %). Rows equal by ``==`` are one (0.0 and -0.0 too; the first of them
    stands for both)."""
    order = np.lexsort(x.T[::-1])
    s = x[order]
    new = np.ones(len(x), bool)
    new[1:] = (s[1:] != s[:-1]).any(axis=1)
    inv = np.empty(len(x), np.intp)
    inv[order] = np.cumsum(new) - 1
    return s[new], inv


def _cached_gap_table(dyn, kind: str, ego: np.ndarray, poses: np.ndarray, gaps_of,
                      reach: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_gap_table` over the plan's distinct poses, memoised on ``dyn`` by them: one decision prices a path
    with several waits (the same poses, repeated) and re-checks it when adopting it."""
    u, inv = _unique_rows(ego)
    key = (kind, u.tobytes(), reach.tobytes())
    hit = dyn._react_cache.get(key)
    if hit is None:
        if len(dyn._react_cache) >= 32:
            dyn._react_cache.clear()
        hit = dyn._react_cache[key] = _gap_table(u, poses, gaps_of, reach)
    rows, g = hit
    return rows, g[:, :, inv.reshape(-1)]


def _roll_out(g: np.ndarray, margin: np.ndarray, react: np.ndarray, steps: int, own_n: np.ndarray,
              hold_last: bool, k0: int, first_only: bool = False,
              ego_closes: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The recurrence of the module docstring for every agent of ``g``: (k, agent row) of every meeting, by time
    then row (``first_only``: of the first time). Only the steps where some gap is finite can brake or meet: before
    them every agent follows its hypothesis (j_k = k - 1), after them nothing happens. ``ego_closes`` (the
    ``overlap`` trigger): an agent that reacts meets the ego within the margin only where the ego's own move from
    step k - 1 brought it nearer to the agent's pose j_k, or where they overlap. Its own approach is its business:
    it brakes before it would overlap, so the ego standing while it comes up is no meeting.

    Both tests of a step are tabled at once over every (agent, j, k) of that window: "brakes" (one of the poses
    j + 1 .. j + L within the reaction distance of the ego's pose k - 1) and "meets" (pose j within the margin of
    the ego's pose k). What is left sequential, each agent's j from step to step, reads the two tables as bytes."""
    a_n, h, n = g.shape
    live = np.nonzero(np.isfinite(g).reshape(-1, n).any(axis=0))[0]
    none = np.zeros(0, np.int64), np.zeros(0, np.int64)
    if a_n == 0 or not len(live):
        return none
    start, end = max(1, int(live[0])), min(n, int(live[-1]) + 1)
    if end <= start:
        return none
    w = g[:, :, start - 1:end]  # the ego's poses start - 1 .. end - 1
    m = end - start + 1
    js = np.arange(-1, h)  # j = -1 (where the agent is) .. h - 1: row j + 1 of the tables
    ahead = np.minimum(js[:, None] + np.arange(1, steps + 1)[None, :], h - 1)  # (h + 1, L)
    # np.take, not w[:, rows, :]: its tables are laid out in C order, which tobytes() then copies as one block
    brakes = np.take(w <= react[:, None, None], ahead, axis=1).any(axis=2)  # (A, h + 1, m): column k - 1, step k
    now = np.take(w, np.maximum(js, 0), axis=1)
    meets = now <= margin[:, None, None]
    if ego_closes:
        before = np.concatenate([np.full((a_n, h + 1, 1), np.nan), now[:, :, :-1]], axis=2)
        meets &= ~np.isfinite(react)[:, None, None] | (now <= 0.0) | (now < before - 1e-9)
    if not hold_last:
        meets &= js[None, :, None] < own_n[:, None, None]
    br, mt = brakes.tobytes(), meets.tobytes()
    j0, last = min(start - 2, h - 1), h - 1
    hit_k, hit_a = [], []
    may_meet = meets[:, :, max(k0 - start + 1, 0):].reshape(a_n, -1).any(axis=1).tolist()
    for a in range(a_n):
        if not may_meet[a]:  # no pose of it meets the ego at any step from k0, wherever it brakes
            continue
        base = a * (h + 1) * m - start + 1  # byte of (a, j + 1, column of step k) = base + (j + 1) * m + k
        j = j0
        for k in range(start, end):
            if not br[base + (j + 1) * m + k - 1]:
                j = j + 1 if j < last else last
            if k >= k0 and mt[base + (j + 1) * m + k]:
                hit_k.append(k), hit_a.append(a)
                if first_only:
                    break
    if not hit_k:
        return none
    k, a = np.array(hit_k, dtype=np.int64), np.array(hit_a, dtype=np.int64)
    if first_only:
        first = k == k.min()
        return k[first], a[first]
    order = np.lexsort((a, k))
    return k[order], a[order]


def reactive_hits(dyn, ego: np.ndarray, vm: np.ndarray, pm: np.ndarray, k0: int, first_only: bool = False):
    """Every meeting of the ego poses ``ego`` (already extended, :meth:`DynamicObstacles._extend`) with the agents
    of ``dyn`` when they stop for the ego (module docstring): (time indices, is a pedestrian, row in its kind's
    arrays, probability), sorted by time, the most probable hypothesis first. ``first_only``: the meetings of the
    first such time of each kind of agent (enough for the first blocking time)."""
    ks, peds, rows_out, probs = [], [], [], []
    steps, extra, overlap = dyn.react_steps, dyn.react_margin, dyn.react_trigger == "overlap"
    if len(dyn.veh_poses):
        reach = dyn.circum + np.hypot(dyn.veh_half[:, 0], dyn.veh_half[:, 1]) + np.maximum(vm, dyn.vm) + extra

        def veh_gaps(e, a, j):
            o = dyn.veh_poses[a, j]
            return rect_gaps(e, o, dyn.half_l, dyn.half_w, dyn.veh_half[a, 0], dyn.veh_half[a, 1])

        rows, g = _cached_gap_table(dyn, "vehicle", ego, dyn.veh_poses, veh_gaps, reach)
        base = 0.0 if overlap else vm[rows]  # the trigger: within the margin, or (§III-B "meets") overlap
        react = np.where(dyn.veh_react[rows], base + extra, -np.inf)  # -inf: never brakes (react_keys)
        k, a = _roll_out(g, vm[rows], react, steps, dyn.veh_n[rows], dyn.hold_last, k0, first_only, overlap)
        ks.append(k), peds.append(np.zeros(len(k), bool)), rows_out.append(rows[a]), probs.append(dyn.veh_prob[rows[a]])
    if len(dyn.ped_pos):
        reach = dyn.circum + dyn.ped_radius + np.maximum(pm, dyn.pm) + extra

        def ped_gaps(e, a, j):
            return disc_gaps(e, dyn.ped_pos[a, j], dyn.half_l, dyn.half_w, dyn.ped_radius[a])

        rows, g = _cached_gap_table(dyn, "pedestrian", ego, dyn.ped_pos, ped_gaps, reach)
        base = 0.0 if overlap else pm[rows]
        react = np.where(dyn.ped_react[rows], base + extra, -np.inf)
        k, a = _roll_out(g, pm[rows], react, steps, dyn.ped_n[rows], dyn.hold_last, k0, first_only, overlap)
        ks.append(k), peds.append(np.ones(len(k), bool)), rows_out.append(rows[a]), probs.append(dyn.ped_prob[rows[a]])
    if not ks:
        return np.zeros(0, np.int64), np.zeros(0, bool), np.zeros(0, np.int64), np.zeros(0)
    k, ped, a, pr = (np.concatenate(x) for x in (ks, peds, rows_out, probs))
    order = np.lexsort((-pr, k))
    return k[order], ped[order], a[order], pr[order]

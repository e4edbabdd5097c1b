"""Collision checking of the ego plan against predicted agents for the planner of §V-D (ROS-free, vectorised).

**Dynamic obstacles** (:class:`DynamicObstacles`): predicted trajectories (§V-C) of vehicles (rectangles)
and pedestrians (discs); ``poses[j]`` is the prediction at t + (j + 1) Δt and a prediction holds its last
pose after its end. An ego pose with time index k (time t + k Δt) is compared with prediction index k - 1;
an ego plan that has ended holds its last pose too.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from avp_collision.reactive import disc_gaps, reactive_hits, rect_gaps
from avp_world.types import PredictedTrajectory


class DynamicObstacles:
    """Time-indexed predicted agents (see the module docstring).

    Args:
        predictions: §V-C predicted trajectories (vehicles: rectangles; pedestrians: discs).
        length, width: the ego footprint.
        vehicle_margin, pedestrian_margin: clearances required.
        commit_steps, risk_bound: the horizon split of mechanism b (:meth:`_violation`); 0 = off.
        hold_after_commit: with ``commit_steps`` > 0, instead of the risk bound each hypothesis is held, after
            the window, at its pose at the window's end (and every meeting blocks): the agents are assumed to stop
            for the ego, as the reactive agents of §III-B do, once the window is past.
    """

    def __init__(
        self,
        predictions: Sequence[PredictedTrajectory],
        length: float,
        width: float,
        vehicle_margin: float = 0.3,
        pedestrian_margin: float = 0.4,
        keep_current_gap: bool = True,
        hold_last: bool = True,
        commit_steps: int = 0,
        risk_bound: float = 0.0,
        hold_after_commit: bool = False,
        react_steps: int = 0,
        react_margin: float = 0.0,
        react_keys: frozenset | set | None = None,
        react_trigger: str = "margin",
    ):
        self.half_l, self.half_w = 0.5 * float(length), 0.5 * float(width)
        self.circum = math.hypot(self.half_l, self.half_w)
        self.vm, self.pm = float(vehicle_margin), float(pedestrian_margin)
        self.keep_current_gap, self.hold_last = bool(keep_current_gap), bool(hold_last)
        self.commit_steps, self.risk_bound = int(commit_steps), float(risk_bound)  # 0: every meeting blocks
        self.react_steps, self.react_margin = int(react_steps), float(react_margin)
        self.react_trigger = str(react_trigger)  # "margin" | "overlap" (avp_collision.reactive)
        if self.commit_steps > 0 and hold_after_commit:  # cut every prediction at the window, held there
            predictions = [replace(p, poses=np.asarray(p.poses, dtype=float)[: self.commit_steps])
                           for p in predictions]
            self.hold_last, self.commit_steps = True, 0
        veh = [p for p in predictions if not p.is_pedestrian and len(p.poses)]
        ped = [p for p in predictions if p.is_pedestrian and len(p.poses)]
        self.horizon = max((len(p.poses) for p in (*veh, *ped)), default=0)
        t = max(self.horizon, 1)

        def pad(a: np.ndarray, cols: int) -> np.ndarray:
            a = np.asarray(a, dtype=float).reshape(-1, 3)[:, :cols]
            return np.concatenate([a, np.repeat(a[-1:], t - len(a), axis=0)]) if len(a) < t else a[:t]

        self.veh_poses = np.array([pad(p.poses, 3) for p in veh]).reshape(len(veh), t, 3)
        self.veh_half = np.array([[0.5 * p.length, 0.5 * p.width] for p in veh]).reshape(len(veh), 2)
        self.veh_ids = [p.agent_id for p in veh]
        self.veh_prob = np.array([float(p.probability) for p in veh])  # the hypotheses' probabilities
        self.ped_pos = np.array([pad(p.poses, 2) for p in ped]).reshape(len(ped), t, 2)
        self.ped_radius = np.array([p.radius for p in ped], dtype=float)
        self.ped_ids = [p.agent_id for p in ped]
        self.ped_prob = np.array([float(p.probability) for p in ped])
        self.veh_n = np.array([len(p.poses) for p in veh], dtype=np.int64)  # own horizons (hold_last=False)
        self.ped_n = np.array([len(p.poses) for p in ped], dtype=np.int64)
        self.veh_react = np.array([react_keys is None or (False, int(i)) in react_keys for i in self.veh_ids], bool)
        self.ped_react = np.array([react_keys is None or (True, int(i)) in react_keys for i in self.ped_ids], bool)
        self._margin_cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}  # by the ego's pose at k = 0
        self._react_cache: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}  # avp_collision.reactive's gap tables

    @property
    def empty(self) -> bool:
        return self.horizon == 0

    def _extend(self, ego: np.ndarray) -> np.ndarray:
        """Ego poses for k = 0..max(K-1, horizon), holding the last pose."""
        ego = np.asarray(ego, dtype=float).reshape(-1, 3)
        n = max(len(ego), self.horizon + 1)
        if len(ego) < n:
            ego = np.concatenate([ego, np.repeat(ego[-1:], n - len(ego), axis=0)])
        return ego

    def _vehicle_gaps(self, ego: np.ndarray, k: np.ndarray, a: np.ndarray) -> np.ndarray:
        """SAT separation (max over the 4 axes of the projected gap) of ego pose k vs vehicle a at index k-1."""
        o = self.veh_poses[a, np.clip(k - 1, 0, self.horizon - 1)]
        return rect_gaps(ego[k], o, self.half_l, self.half_w, self.veh_half[a, 0], self.veh_half[a, 1])

    def _ped_gaps(self, ego: np.ndarray, k: np.ndarray, a: np.ndarray) -> np.ndarray:
        q = self.ped_pos[a, np.clip(k - 1, 0, self.horizon - 1)]
        return disc_gaps(ego[k], q, self.half_l, self.half_w, self.ped_radius[a])

    def _pairs(self, ego: np.ndarray, centres: np.ndarray, reach: np.ndarray, k0: int, own_n: np.ndarray):
        """Candidate (k, agent) pairs whose centres are within reach (k >= k0). With ``hold_last`` an agent
        stays at its last predicted pose after its horizon; without, it is no obstacle after ``own_n`` steps."""
        n = len(ego)
        k = np.arange(k0, n)
        j = np.clip(k - 1, 0, self.horizon - 1)
        d = centres[:, j, :] - ego[None, k0:, :2]  # (A, n - k0, 2)
        near = np.einsum("akd,akd->ak", d, d) <= (reach[:, None]) ** 2
        if not self.hold_last:
            near &= (k - 1)[None, :] < own_n[:, None]
        aa, kk = np.nonzero(near)
        return kk + k0, aa

    def _margins(self, ego0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-agent margins: the nominal one, or, for an agent already closer than that to the ego's current
        pose (say a reactive car that stopped next to it), its current gap less 5 cm (never below 0), so
        that the ego may still move away instead of being frozen next to it (``keep_current_gap``; off: the
        nominal margin for every agent, the paper's rule). Memoised by ego0: one decision prices every candidate
        from the same pose."""
        key = np.asarray(ego0, dtype=float).tobytes()
        hit = self._margin_cache.get(key)
        if hit is None:
            if len(self._margin_cache) >= 64:
                self._margin_cache.clear()
            hit = self._margin_cache[key] = self._compute_margins(ego0)
        return hit

    def _compute_margins(self, ego0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pair = np.stack([ego0, ego0])
        vm = np.full(len(self.veh_poses), self.vm)
        pm = np.full(len(self.ped_pos), self.pm)
        if not self.keep_current_gap:
            return vm, pm
        if len(vm):
            a = np.arange(len(vm))
            g = self._vehicle_gaps(pair, np.ones(len(vm), dtype=np.int64), a)
            vm = np.where(g < self.vm, np.maximum(g - 0.05, 0.0), self.vm)
        if len(pm):
            a = np.arange(len(pm))
            g = self._ped_gaps(pair, np.ones(len(pm), dtype=np.int64), a)
            pm = np.where(g < self.pm, np.maximum(g - 0.05, 0.0), self.pm)
        return vm, pm

    def _hits(self, ego_poses: np.ndarray, k0: int = 1,
              first_only: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Every meeting (k >= k0, the ego holding its last pose) of the ego with a predicted agent, i.e. within
        the margin of it (see :meth:`_margins` for agents already that close at k = 0): (time indices, is a
        pedestrian, row in its kind's arrays, probability of that hypothesis), sorted by k."""
        empty = (np.zeros(0, np.int64), np.zeros(0, bool), np.zeros(0, np.int64), np.zeros(0))
        if self.empty:
            return empty
        ego = self._extend(ego_poses)
        vm, pm = self._margins(ego[0])
        if self.react_steps <= 0 or not (self.veh_react.any() or self.ped_react.any()):
            return self._plain_hits(ego, vm, pm, k0)
        # agents stop for the ego (avp_collision.reactive), after a commit window in which they are assumed not to
        late = reactive_hits(self, ego, vm, pm, max(k0, self.commit_steps + 1), first_only)
        if self.commit_steps <= 0 or k0 > self.commit_steps:
            return late
        early = self._plain_hits(ego[: self.commit_steps + 1], vm, pm, k0)
        k, ped, a, pr = (np.concatenate(x) for x in zip(early, late, strict=True))
        order = np.lexsort((-pr, k))
        return k[order], ped[order], a[order], pr[order]

    def _plain_hits(self, ego: np.ndarray, vm: np.ndarray, pm: np.ndarray, k0: int):
        """:meth:`_hits` with every agent following its hypothesis whatever the ego does (the paper)."""
        empty = (np.zeros(0, np.int64), np.zeros(0, bool), np.zeros(0, np.int64), np.zeros(0))
        ks, peds, rows, probs = [], [], [], []
        if len(self.veh_poses):
            reach = self.circum + np.hypot(self.veh_half[:, 0], self.veh_half[:, 1]) + self.vm
            k, a = self._pairs(ego, self.veh_poses[..., :2], reach, k0, self.veh_n)
            if len(k):
                hit = self._vehicle_gaps(ego, k, a) <= vm[a]
                ks.append(k[hit]), peds.append(np.zeros(int(hit.sum()), bool)), rows.append(a[hit])
                probs.append(self.veh_prob[a[hit]])
        if len(self.ped_pos):
            reach = self.circum + self.ped_radius + self.pm
            k, a = self._pairs(ego, self.ped_pos, reach, k0, self.ped_n)
            if len(k):
                hit = self._ped_gaps(ego, k, a) <= pm[a]
                ks.append(k[hit]), peds.append(np.ones(int(hit.sum()), bool)), rows.append(a[hit])
                probs.append(self.ped_prob[a[hit]])
        if not ks:
            return empty
        k, ped, a, pr = (np.concatenate(x) for x in (ks, peds, rows, probs))
        order = np.lexsort((-pr, k))  # by time, the most probable hypothesis first
        return k[order], ped[order], a[order], pr[order]

    def collision_steps(self, ego_poses: np.ndarray, k0: int = 1) -> np.ndarray:
        """Sorted time indices k >= k0 at which the ego (holding its last pose) meets a predicted agent."""
        return np.unique(self._hits(ego_poses, k0)[0])

    def _violation(self, hits: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]) -> tuple[int, int]:
        """(first blocking k, index into ``hits`` (:meth:`_hits`) of the meeting that blocks) or (-1, -1). Without
        a commit window every meeting blocks. With one (``commit_steps`` > 0, mechanism b), a meeting
        within it blocks; beyond it, the plan is blocked at the first k by which the hypotheses met (each counted
        once) sum to more than ``risk_bound`` in probability."""
        k, ped, a, pr = hits
        if not len(k):
            return -1, -1
        if self.commit_steps <= 0 or self.react_steps > 0:  # with the agents' reaction every meeting blocks
            return int(k[0]), 0
        hard = np.nonzero(k <= self.commit_steps)[0]
        if len(hard):
            return int(k[hard[0]]), int(hard[0])
        seen: set[tuple[bool, int]] = set()
        risk = 0.0
        for i in range(len(k)):
            key = (bool(ped[i]), int(a[i]))
            if key not in seen:
                seen.add(key)
                risk += float(pr[i])
                if risk > self.risk_bound + 1e-12:
                    return int(k[i]), i
        return -1, -1

    def blocker(self, ego_poses: np.ndarray, k0: int = 1) -> tuple[int, bool, int, float] | None:
        """Who blocks the ego's poses (for the decision trace): (time index k, is a pedestrian, agent id,
        probability of that hypothesis) of the meeting that makes :meth:`first_collision` fail, or None."""
        hits = self._hits(ego_poses, k0, first_only=True)
        k, i = self._violation(hits)
        if k < 0:
            return None
        _, ped, a, pr = hits
        ids = self.ped_ids if ped[i] else self.veh_ids
        return k, bool(ped[i]), int(ids[int(a[i])]), float(pr[i])

    def first_collision(self, ego_poses: np.ndarray, k0: int = 1) -> int:
        """First time index (>= k0) at which the poses are blocked (see :meth:`_violation`), or -1."""
        return self._violation(self._hits(ego_poses, k0, first_only=True))[0]

    def proximity_cost(self, ego_poses: np.ndarray, dt: float, decay: float = 2.0, reach: float = 3.0) -> float:
        """sum_k sum_agents exp(-decay * gap) dt over pairs closer than ``reach`` (gap: SAT lower bound)."""
        if self.empty:
            return 0.0
        ego = self._extend(ego_poses)
        total = 0.0
        if len(self.veh_poses):
            r = self.circum + np.hypot(self.veh_half[:, 0], self.veh_half[:, 1]) + reach
            k, a = self._pairs(ego, self.veh_poses[..., :2], r, 1, self.veh_n)
            if len(k):
                g = self._vehicle_gaps(ego, k, a)
                g = g[g < reach]
                total += float(np.exp(-decay * np.maximum(g, 0.0)).sum())
        if len(self.ped_pos):
            r = self.circum + self.ped_radius + reach
            k, a = self._pairs(ego, self.ped_pos, r, 1, self.ped_n)
            if len(k):
                g = self._ped_gaps(ego, k, a)
                g = g[g < reach]
                total += float(np.exp(-decay * np.maximum(g, 0.0)).sum())
        return total * dt

"""Collision checking of the ego plan against predicted agents for the planner of §V-D (ROS-free, vectorised).

**Dynamic obstacles** (:class:`DynamicObstacles`): predicted trajectories (§V-C) of vehicles (rectangles)
and pedestrians (discs); ``poses[j]`` is the prediction at t + (j + 1) Δt and a prediction holds its last
pose after its end. An ego pose with time index k (time t + k Δt) is compared with prediction index k - 1;
an ego plan that has ended holds its last pose too.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from avp_world.types import PredictedTrajectory


class DynamicObstacles:
    """Time-indexed predicted agents (see the module docstring).

    Args:
        predictions: §V-C predicted trajectories (vehicles: rectangles; pedestrians: discs).
        length, width: the ego footprint.
        vehicle_margin, pedestrian_margin: clearances required.
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
    ):
        self.half_l, self.half_w = 0.5 * float(length), 0.5 * float(width)
        self.circum = math.hypot(self.half_l, self.half_w)
        self.vm, self.pm = float(vehicle_margin), float(pedestrian_margin)
        self.keep_current_gap, self.hold_last = bool(keep_current_gap), bool(hold_last)
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
        self.veh_prob = [float(p.probability) for p in veh]  # the hypotheses' probabilities (decision trace)
        self.ped_pos = np.array([pad(p.poses, 2) for p in ped]).reshape(len(ped), t, 2)
        self.ped_radius = np.array([p.radius for p in ped], dtype=float)
        self.ped_ids = [p.agent_id for p in ped]
        self.ped_prob = [float(p.probability) for p in ped]
        self.veh_n = np.array([len(p.poses) for p in veh], dtype=np.int64)  # own horizons (hold_last=False)
        self.ped_n = np.array([len(p.poses) for p in ped], dtype=np.int64)
        self._margin_cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}  # by the ego's pose at k = 0

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
        j = np.clip(k - 1, 0, self.horizon - 1)
        o = self.veh_poses[a, j]
        tx, ty = o[:, 0] - ego[k, 0], o[:, 1] - ego[k, 1]
        c, s = np.cos(ego[k, 2]), np.sin(ego[k, 2])
        oc, os_ = np.cos(o[:, 2]), np.sin(o[:, 2])
        bl, bw = self.veh_half[a, 0], self.veh_half[a, 1]
        al, aw = self.half_l, self.half_w
        cd = np.abs(c * oc + s * os_)
        sd = np.abs(s * oc - c * os_)
        return np.maximum.reduce([
            np.abs(tx * c + ty * s) - (al + bl * cd + bw * sd),
            np.abs(-tx * s + ty * c) - (aw + bl * sd + bw * cd),
            np.abs(tx * oc + ty * os_) - (bl + al * cd + aw * sd),
            np.abs(-tx * os_ + ty * oc) - (bw + al * sd + aw * cd),
        ])

    def _ped_gaps(self, ego: np.ndarray, k: np.ndarray, a: np.ndarray) -> np.ndarray:
        j = np.clip(k - 1, 0, self.horizon - 1)
        q = self.ped_pos[a, j]
        dx, dy = q[:, 0] - ego[k, 0], q[:, 1] - ego[k, 1]
        c, s = np.cos(ego[k, 2]), np.sin(ego[k, 2])
        lx = np.maximum(np.abs(dx * c + dy * s) - self.half_l, 0.0)
        ly = np.maximum(np.abs(-dx * s + dy * c) - self.half_w, 0.0)
        return np.hypot(lx, ly) - self.ped_radius[a]

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

    def collision_steps(self, ego_poses: np.ndarray, k0: int = 1) -> np.ndarray:
        """Sorted time indices k >= k0 at which the ego (holding its last pose) meets a predicted agent,
        i.e. comes within the margin of it (see :meth:`_margins` for agents already that close at k = 0)."""
        if self.empty:
            return np.zeros(0, dtype=np.int64)
        ego = self._extend(ego_poses)
        vm, pm = self._margins(ego[0])
        hits = []
        if len(self.veh_poses):
            reach = self.circum + np.hypot(self.veh_half[:, 0], self.veh_half[:, 1]) + self.vm
            k, a = self._pairs(ego, self.veh_poses[..., :2], reach, k0, self.veh_n)
            if len(k):
                hits.append(k[self._vehicle_gaps(ego, k, a) <= vm[a]])
        if len(self.ped_pos):
            reach = self.circum + self.ped_radius + self.pm
            k, a = self._pairs(ego, self.ped_pos, reach, k0, self.ped_n)
            if len(k):
                hits.append(k[self._ped_gaps(ego, k, a) <= pm[a]])
        if not hits:
            return np.zeros(0, dtype=np.int64)
        return np.unique(np.concatenate(hits))

    def blocker(self, ego_poses: np.ndarray, k0: int = 1) -> tuple[int, bool, int, float] | None:
        """Who meets the ego first (issue #28's decision trace): (time index k, is a pedestrian, agent id,
        probability of that hypothesis) of the earliest colliding pair (the most probable hypothesis at that
        k), or None. The same pairs and gaps as :meth:`collision_steps`."""
        if self.empty:
            return None
        ego = self._extend(ego_poses)
        vm, pm = self._margins(ego[0])
        best: tuple | None = None
        for is_ped in (False, True):
            n = len(self.ped_pos) if is_ped else len(self.veh_poses)
            if not n:
                continue
            if is_ped:
                reach = self.circum + self.ped_radius + self.pm
                k, a = self._pairs(ego, self.ped_pos, reach, k0, self.ped_n)
                hit = self._ped_gaps(ego, k, a) <= pm[a] if len(k) else np.zeros(0, bool)
            else:
                reach = self.circum + np.hypot(self.veh_half[:, 0], self.veh_half[:, 1]) + self.vm
                k, a = self._pairs(ego, self.veh_poses[..., :2], reach, k0, self.veh_n)
                hit = self._vehicle_gaps(ego, k, a) <= vm[a] if len(k) else np.zeros(0, bool)
            ids, probs = (self.ped_ids, self.ped_prob) if is_ped else (self.veh_ids, self.veh_prob)
            for kk, aa in zip(k[hit].tolist(), a[hit].tolist(), strict=True):
                key = (kk, -probs[aa])
                if best is None or key < best[0]:
                    best = (key, (int(kk), is_ped, int(ids[aa]), probs[aa]))
        return None if best is None else best[1]

    def first_collision(self, ego_poses: np.ndarray, k0: int = 1) -> int:
        """First colliding time index (>= k0), or -1."""
        steps = self.collision_steps(ego_poses, k0)
        return int(steps[0]) if len(steps) else -1

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

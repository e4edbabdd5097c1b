"""The agents of the training traffic (:mod:`.traffic`): parkers that drive to a spot and park with one of the 8
ParkSim maneuvers, explorers that wander the lanes before parking, and leavers that pull out of a spot and drive
to the exit. Methods of :class:`~.traffic.TrafficGenerator` (split by job).
"""

from __future__ import annotations

import math

import numpy as np

from avp_scenario.maneuvers import ManeuverKey
from avp_traffic.lanes import A_DEC, Path, follow, rollout
from avp_traffic.types import LEAVE, PARK, WANDER, AgentPlan, moving_flags, slow_tail
from avp_world.geometry import rect_corners, rect_inside_rect


class AgentPlannersMixin:
    """Methods of :class:`~.traffic.TrafficGenerator`; see the module docstring."""

    def _parker(self, rng: np.random.Generator, k0: int, free_from: np.ndarray, reserved: np.ndarray
                ) -> AgentPlan | None:
        """A car from the queue: goal-directed (1 - ``p_explore``, ParkSim's task-based drivers) or exploring."""
        if rng.random() < self.p.p_explore:
            return self._explorer(rng, k0, free_from, reserved)
        return self._goal_parker(rng, k0, free_from, reserved)

    def _maneuver_on_lane(self, rng: np.random.Generator, row: int, side: str, lane: int, t_in: float,
                          brake_d: float) -> tuple | None:
        """(row, key, world maneuver, t_s) for parking in ``row`` from ``lane`` joined at ``t_in``: stop before
        (``p_stop_before``) or after the spot, head-in or tail-in (``p_head_in``), the other options as fall-backs;
        the maneuver must start at least ``brake_d`` into the lane. None if no option fits."""
        p, cur = self.p, self.graph.lanes[lane]
        stops = ["before", "after"] if rng.random() < p.p_stop_before else ["after", "before"]
        entries = ["head_in", "tail_in"] if rng.random() < p.p_head_in else ["tail_in", "head_in"]
        for stop in stops:
            for entry in entries:
                key = ManeuverKey(side, stop, entry)
                man = self.lib.world(row, key, p.dt)
                if man is None:
                    continue
                t_s = float((man[0][:2] - cur.a) @ cur.d)
                if t_in + brake_d <= t_s <= cur.length + 1.0:
                    return row, key, man, t_s
        return None

    def _goal_parker(self, rng: np.random.Generator, k0: int, free_from: np.ndarray, reserved: np.ndarray
                     ) -> AgentPlan | None:
        """ParkSim's task-based driver (reference sheet §3.3): a spot chosen at the entrance among those free at
        the estimated arrival (weight exp(-d / L) over the route length d, L ~ ``preference_length`` per
        driver, x ``far_factor`` across the aisle), the shortest lane route to it, then the maneuver."""
        p, g = self.p, self.graph
        v_c = float(rng.uniform(*p.cruise_speed))
        pref = float(rng.uniform(*p.preference_length))
        t0 = self._time(k0) + p.queue_distance / p.approach_speed
        brake_d = v_c**2 / (2.0 * A_DEC) + 0.5
        options, weights = [], []
        for row, items in self.spot_lanes.items():
            for lane, t_k, side in items:
                if lane not in self.entry_dist:
                    continue
                d = self.entry_dist[lane] + t_k
                if not self._available(row, t0 + d / (0.8 * v_c), free_from, reserved):
                    continue
                options.append((row, lane, side))
                weights.append(math.exp(-d / pref) * (p.far_factor if side == "far" else 1.0))
        if not options:
            self.why["no_free_spot"] += 1
            return None
        w = np.asarray(weights)
        for i in rng.choice(len(options), size=min(3, len(options)), replace=False, p=w / w.sum()):
            row, lane, side = options[int(i)]
            lanes = self.entry_routes[lane]
            t_in = g.turns[(lanes[-2], lane)].t2 if len(lanes) > 1 else 0.0
            chosen = self._maneuver_on_lane(rng, row, side, lane, t_in, brake_d)
            if chosen is not None:
                plan = self._park_plan(rng, k0, lanes, chosen, v_c)
                if plan is not None:
                    plan.goal_options, plan.goal_weights = tuple(options), w
                return plan
        self.why["goal_maneuver"] += 1
        return None

    def _explorer(self, rng: np.random.Generator, k0: int, free_from: np.ndarray, reserved: np.ndarray
                  ) -> AgentPlan | None:
        """An exploring driver (module docstring): takes a passed free spot with a growing probability or gives
        up and leaves (a wanderer)."""
        p, g = self.p, self.graph
        v_c = float(rng.uniform(*p.cruise_speed))
        p_driver = float(rng.uniform(*p.p_take))
        give_up = float(rng.uniform(*p.give_up))
        t0 = self._time(k0) + p.queue_distance / p.approach_speed  # time at the entrance
        brake_d = v_c**2 / (2.0 * A_DEC) + 0.5
        lanes = [g.entry]
        visits = {g.entry: 1}
        t_in = 0.0  # lane coordinate where the car joins the current lane
        dist = 0.0  # driven since the entrance (to the joining point)
        chosen = None
        while chosen is None:
            cur = g.lanes[lanes[-1]]
            if cur.road >= 0:
                for row, t_k, side in g.spot_lanes[cur.id]:
                    if t_k < t_in + 2.0:
                        continue
                    travelled = dist + t_k - t_in
                    t_arrive = t0 + travelled / (0.8 * v_c)
                    if not self._available(row, t_arrive, free_from, reserved):
                        continue
                    prob = 1.0 - (1.0 - p_driver) * math.exp(-(travelled / v_c) / p.patience)
                    if side == "far":
                        prob *= p.far_factor
                    if rng.random() >= prob:
                        continue
                    chosen = self._maneuver_on_lane(rng, row, side, cur.id, t_in, brake_d)
                    if chosen:
                        break
            if chosen:
                break
            dist += cur.length - t_in
            if dist > give_up:
                break
            opts = [n for n in g.nexts[cur.id] if n in self.walk_lanes]
            if not opts:
                self.why["no_lane"] += 1
                return None
            w = np.ones(len(opts))
            for i, n in enumerate(opts):
                w[i] *= 0.25 ** visits.get(n, 0)
                t_est = t0 + dist / (0.8 * v_c)
                if any(self._available(r, t_est, free_from, reserved) for r, _, _ in g.spot_lanes[n]):
                    w[i] *= 2.5
            nxt = int(opts[int(rng.choice(len(opts), p=w / w.sum()))])
            t_in = g.turns[(cur.id, nxt)].t2
            lanes.append(nxt)
            visits[nxt] = visits.get(nxt, 0) + 1
        if chosen is not None:
            return self._park_plan(rng, k0, lanes, chosen, v_c)
        start = self._queue_start()
        lanes = lanes[:-1] + g.shortest(lanes[-1], g.exit)  # a wanderer: leave by the shortest way
        try:
            s, pieces = g.route_pieces(lanes, -p.queue_distance, g.lanes[g.exit].length + p.exit_distance, v_c,
                                       {g.entry: p.approach_speed})
        except (ValueError, KeyError):
            self.why["wander_route"] += 1
            return None
        u, _ = follow(Path.build(s, pieces), start, p.dt, self.vehicle)
        u_full, x_full = self._pad(k0, start, u)
        return AgentPlan(WANDER, -1, "", x_full, u_full, moving_flags(x_full))

    def _queue_start(self) -> np.ndarray:
        entry = self.graph.lanes[self.graph.entry]
        queue = np.asarray(entry.point(-self.p.queue_distance))
        return np.array([queue[0], queue[1], entry.heading])

    def _park_plan(self, rng: np.random.Generator, k0: int, lanes: list[int], chosen: tuple, v_c: float
                   ) -> AgentPlan | None:
        """From the queue along ``lanes`` at ``v_c``, slowing to U[slow_speed] over the last U[slow_distance] m,
        to the maneuver start; a pause, then the maneuver ``chosen`` = (row, key, world maneuver, t_s)."""
        p, g = self.p, self.graph
        row, key, man, t_s = chosen
        start = self._queue_start()
        try:
            s, pieces = g.route_pieces(lanes, -p.queue_distance, t_s, v_c, {g.entry: p.approach_speed})
        except ValueError:
            self.why["park_route"] += 1
            return None
        roll = float(rng.uniform(*p.slow_distance))
        pieces = slow_tail(pieces, roll, float(rng.uniform(*p.slow_speed)))
        u_drive, x_drive = follow(Path.build(s, pieces), start, p.dt, self.vehicle)
        pause = np.zeros((int(round(rng.uniform(*p.pause) / p.dt)), 2))
        controls = np.concatenate([u_drive, pause, man[2]])
        u_full, x_full = self._pad(k0, start, controls)
        end = rect_corners(rollout(x_drive[-1], man[2], p.dt)[-1], self.vehicle.length, self.vehicle.width)
        if not rect_inside_rect(end[None], self.lot.spot_corners[row][None])[0]:  # (the episode may end first)
            self.why["not_in_spot"] += 1
            return None
        return AgentPlan(PARK, row, "/".join(key), x_full, u_full, moving_flags(x_full),
                         drive_end=k0 + len(u_drive) - 1, end_lane=lanes[-1], end_t=t_s, cruise_speed=v_c,
                         roll_distance=roll)

    # ------------------------------------------------------------------ leavers
    def _leaver(self, rng: np.random.Generator, row: int, k0: int) -> AgentPlan | None:
        p, g = self.p, self.graph
        v_c = float(rng.uniform(*p.cruise_speed))
        options = [(lane, t, side, stop, entry) for lane, t, side in self.spot_lanes.get(row, [])
                   for stop in ("before", "after") for entry in ("head_in", "tail_in")]
        for i in rng.permutation(len(options)):
            lane, _, side, stop, entry = options[int(i)]
            key = ManeuverKey(side, stop, entry)
            man = self.lib.world(row, key, p.dt)
            if man is None:
                continue
            ln = g.lanes[lane]
            t_s = float((man[0][:2] - ln.a) @ ln.d)
            if not 0.0 <= t_s <= ln.length + 1.0:
                continue
            parked = man[1][-1]
            unpark = -man[2][::-1]
            x_un = rollout(parked, unpark, p.dt)
            try:
                seq = g.shortest(lane, g.exit)
                s, pieces = g.route_pieces(seq, t_s, g.lanes[g.exit].length + p.exit_distance, v_c)
            except (ValueError, KeyError):
                continue
            u_out, _ = follow(Path.build(s, pieces), x_un[-1], p.dt, self.vehicle)
            u_full, x_full = self._pad(k0, parked, np.concatenate([unpark, u_out]))
            return AgentPlan(LEAVE, row, "/".join(key), x_full, u_full, moving_flags(x_full))
        return None

    # ------------------------------------------------------------------ ego

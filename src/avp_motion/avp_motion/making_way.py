"""``make_way`` (mechanism e): step out of the way of an agent that stands because the ego is in its path.

The gridlock of the busy lot (docs/research/unfreezing.md): a reactive car (§III-B) stands
because its next poses meet the ego, and the ego stands because that car blocks every plan. The simulator's agents
never back off or re-plan, so the gridlock is permanent unless the ego moves. A standing car's Bézier hypotheses are
standing too (§V-C follows the curve at the car's own speed, 0), so nothing predicted says the ego is in its way;
its heading does: the car will drive on along it.

After the ego has stood ``make_way_after`` s, every observed dynamic car that stands within reach and whose
**corridor** — its footprint swept ``make_way_reach`` m along its direction of travel (forward, or backward if it
last moved backward), widened by the vehicle margin — overlaps the ego's footprint is a car the ego is in the way of.
So is a standing pedestrian, as a square of its diameter facing the way it last walked (the planner remembers it;
a pedestrian never seen walking is left out), widened by the pedestrian margin.
The ego then drives the shortest short manoeuvre (one arc or an S of two opposite arcs, forward or reverse,
``MOVES``) that

* is free of the static world (``verify_margin``) and meets no predicted agent over the prediction horizon (the
  ego holding its end pose), and
* ends with the ego's footprint clear of those cars' corridors swept ``make_way_clear`` m,

then stands there (the trace's cause ``making_way``) until those agents have left their place by 1 m, or for
``make_way_hold`` s at most. The paper's sentence it departs from: §V-D-3 "the ego would stay put at the current
position". Off by default and under every protocol; `--ablation` names it ``make_way``.
"""

from __future__ import annotations

import math
import time

import numpy as np

from avp_collision.reactive import rect_gaps
from avp_motion.control import track
from avp_motion.planner_inputs import pedestrian_stands, vehicle_stands
from avp_motion.planner_search import start_relaxed_margins
from avp_motion.planner_types import EXPLORE, IDLE, Decision, _Plan
from avp_search.paths import Path

#: the manoeuvres tried: (length of the first arc, length of the second, opposite-curvature arc) in m; 0 = one arc
MOVES = ((2.0, 0.0), (3.0, 0.0), (4.0, 0.0), (6.0, 0.0), (2.0, 2.0), (3.0, 3.0), (4.0, 4.0))
MOVED_AWAY = 1.0  # m a blocking agent has to leave its place by before the ego stops standing aside
RETRY_STEPS = 10  # after a failed search for a way out, the next one is this many steps later
PED_MEMORY = 256  # pedestrians whose last walking direction is remembered


def travel_sign(history: np.ndarray) -> float:
    """+1 if the car's last move (over 1 mm) was forward along its heading, -1 if backward; +1 if it never moved."""
    h = np.asarray(history, dtype=float).reshape(-1, 3)
    for i in range(len(h) - 1, 0, -1):
        d = h[i, :2] - h[i - 1, :2]
        if math.hypot(*d) > 1e-3:
            return 1.0 if d[0] * math.cos(h[i, 2]) + d[1] * math.sin(h[i, 2]) >= 0.0 else -1.0
    return 1.0


def corridor(pose: np.ndarray, length: float, width: float, sign: float, reach: float,
             margin: float) -> tuple[np.ndarray, float, float]:
    """The car's footprint swept ``reach`` m along ``sign`` × its heading and grown by ``margin`` a side, as one
    rectangle: (centre pose (3,), half length, half width)."""
    c = np.asarray(pose, dtype=float).copy()
    c[:2] += sign * 0.5 * reach * np.array([math.cos(c[2]), math.sin(c[2])])
    return c, 0.5 * length + 0.5 * reach + margin, 0.5 * width + margin


class MakeWayMixin:
    """Methods of :class:`~avp_planner.core.decision.EgoPlanner`; see the module docstring."""

    def _remember_headings(self, obs) -> None:
        """The direction each observed pedestrian last walked in (it has no heading of its own; a standing one
        keeps the last), at most ``PED_MEMORY`` of them."""
        for p in obs.pedestrians:
            d = np.asarray(p.position, dtype=float) - np.asarray(p.previous_position, dtype=float)
            if math.hypot(*d) > 1e-3:
                self._ped_heading.pop(int(p.id), None)
                self._ped_heading[int(p.id)] = math.atan2(d[1], d[0])
        while len(self._ped_heading) > PED_MEMORY:
            self._ped_heading.pop(next(iter(self._ped_heading)))

    def _standing_agents(self, obs) -> list[tuple]:
        """The observed dynamic agents that stand: ((is a pedestrian, id), pose (3,), length, width, travel sign).
        A pedestrian is a square of its diameter facing the way it last walked (skipped if it never did)."""
        out = []
        for v in obs.vehicles:
            if vehicle_stands(v, obs.dt):
                h = np.asarray(v.history, dtype=float).reshape(-1, 3)
                out.append(((False, int(v.id)), h[-1].copy(), float(v.length), float(v.width), travel_sign(h)))
        for p in obs.pedestrians:
            if pedestrian_stands(p, obs.dt) and int(p.id) in self._ped_heading:
                q = np.asarray(p.position, dtype=float)
                pose = np.array([q[0], q[1], self._ped_heading[int(p.id)]])
                out.append(((True, int(p.id)), pose, 2.0 * p.radius, 2.0 * p.radius, 1.0))
        return out

    def _blockers_waiting(self, obs, ego: np.ndarray, reach: float) -> list[tuple]:
        """The standing agents whose corridor (``reach`` m) overlaps the ego's footprint (see
        :meth:`_standing_agents` for the rows)."""
        hl, hw, c = 0.5 * obs.ego_length, 0.5 * obs.ego_width, self.settings.collision
        out = []
        for key, pose, length, width, sign in self._standing_agents(obs):
            if math.hypot(*(pose[:2] - ego[:2])) > reach + length + obs.ego_length:
                continue
            margin = c.pedestrian_margin if key[0] else c.vehicle_margin
            zc, zl, zw = corridor(pose, length, width, sign, reach, margin)
            if float(rect_gaps(ego, zc, hl, hw, zl, zw)) < 0.0:
                out.append((key, pose, length, width, sign))
        return out

    def _make_way(self, st) -> _Plan | None:
        """Once stood ``make_way_after`` s: the shortest manoeuvre out of the corridors of the agents waiting for the
        ego (see the module docstring), or None (none waits, or no manoeuvre is safe)."""
        d, k = self.settings.decision, self.settings.control
        if (not d.make_way or self._stuck_steps * k.dt < d.make_way_after - 1e-9
                or st.obs.step < self._make_way_retry):
            return None
        t0 = time.perf_counter()
        ego, obs = st.ego, st.obs
        blockers = self._blockers_waiting(obs, ego, d.make_way_reach)
        plan = None
        if blockers:
            plan = self._way_out(ego, obs, st, blockers)
            if plan is None:
                self._make_way_retry = obs.step + RETRY_STEPS
        st.timing["spot_selection_time"] += time.perf_counter() - t0
        if plan is not None:
            self._make_way_for = [(b[0], b[1][:2].copy()) for b in blockers]
            self._make_way_until = obs.step + len(plan.traj.controls) + int(round(d.make_way_hold / k.dt))
            ids = ", ".join(f"{'pedestrian' if b[0][0] else 'car'} {b[0][1]}" for b in blockers)
            plan.note = f"making way for {ids} waiting for the ego (make_way)"
        return plan

    def _way_out(self, ego, obs, st, blockers) -> _Plan | None:
        """The shortest safe manoeuvre of ``MOVES`` whose end pose is clear of every blocker's corridor."""
        d, c = self.settings.decision, self.settings.collision
        zones = [corridor(p, ln, wd, s, d.make_way_clear, c.pedestrian_margin if key[0] else c.vehicle_margin)
                 for key, p, ln, wd, s in blockers]
        return self._way_out_of(ego, obs, st, zones)

    def _way_out_of(self, ego, obs, st, zones: list[tuple]) -> _Plan | None:
        """The shortest safe manoeuvre of ``MOVES`` whose end pose is clear of every zone (centre pose, half length,
        half width), free of the static world and of every predicted agent; None if there is none."""
        c = self.settings.collision
        hl, hw = 0.5 * obs.ego_length, 0.5 * obs.ego_width
        kap = 1.0 / self.settings.plan_radius
        start = (float(ego[0]), float(ego[1]), float(ego[2]))
        if zones:
            zc = np.array([z[0] for z in zones], dtype=float).reshape(-1, 3)
            zl, zw = np.array([z[1] for z in zones], dtype=float), np.array([z[2] for z in zones], dtype=float)
        paths = []
        for direction in (-1.0, 1.0):
            for f in self.settings.search.steering_fractions:
                for first, second in MOVES:
                    if second and f == 0.0:
                        continue
                    segs = ((f * kap, direction * first),) + (((-f * kap, direction * second),) if second else ())
                    paths.append(Path(start, segs))
        paths.sort(key=lambda p: (p.length, p.segments[0][1] < 0))
        for path in paths:
            end = np.asarray(path.end(), dtype=float)
            if len(zones) and (rect_gaps(end[None], zc, hl, hw, zl, zw) < 0.0).any():
                continue
            traj = track(path, self.settings.control, self.settings.vehicle.max_curvature, obs.ego_speed)
            x = traj.states
            margins = start_relaxed_margins(x, c)  # boxed in: the first metres relaxed as _adopt does
            if not st.world.free_xyc(x[:, 0], x[:, 1], np.cos(x[:, 2]), np.sin(x[:, 2]), margins).all():
                continue
            if not st.dyn.empty and st.dyn.first_collision(traj.states) >= 0:
                continue
            return _Plan(EXPLORE, -1, end, traj, math.inf, margins, 0, path.length, kind="make_way")
        return None

    def _aside_decision(self, obs, beliefs) -> Decision | None:
        """The idle decision of a step the ego stands aside after making way (the trace's cause ``making_way``,
        naming the agent), or None. The step the manoeuvre ends in drops its plan first."""
        p = self._plan
        if p is not None and p.kind == "make_way" and p.index >= len(p.traj.controls):
            self._plan = None
        aside = self._standing_aside(obs) if self._plan is None else None
        if aside is None:
            return None
        if beliefs is None:
            self.update_beliefs(obs)
        who = f"{'pedestrian' if aside[0] else 'car'} {aside[1]}"
        return Decision(IDLE, reason=f"standing aside for {who} (make_way)",
                        poses=np.asarray(obs.ego_pose, float)[None].copy(),
                        trace={"mode": IDLE, "cause": "making_way", "agent_id": aside[1], "pedestrian": aside[0]})

    def _standing_aside(self, obs) -> tuple[bool, int] | None:
        """While the ego stands aside after making way: the key of an agent it waits for that has not yet left its
        place by ``MOVED_AWAY`` m (and is still seen), until ``make_way_hold`` s after the manoeuvre ended; else
        None (and the wait is over)."""
        if not self._make_way_for:
            return None
        if obs.step >= self._make_way_until:
            self._make_way_for = []
            return None
        seen = {(False, int(v.id)): np.asarray(v.history, dtype=float).reshape(-1, 3)[-1, :2] for v in obs.vehicles}
        seen.update({(True, int(p.id)): np.asarray(p.position, dtype=float) for p in obs.pedestrians})
        for key, where in self._make_way_for:
            if key in seen and math.hypot(*(seen[key] - where)) < MOVED_AWAY:
                return key
        self._make_way_for = []
        return None

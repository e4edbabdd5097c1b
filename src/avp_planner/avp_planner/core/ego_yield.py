"""``ego_yield``: give way to an automated car with the right of way that stands waiting for the ego (fleets only).

Two egos of one fleet can stand face to face for good: each is the other's blocker, each plans as §III-B says the
other cars behave (they stop for the ego), and neither is a car that ever backs off (docs/results/fleet/README.md:
the gridlock of seed 29 at K = 4). An ego cannot tell another ego from a person's car by observation alone, so this
rule reads a **message between egos**: every ego of a fleet announces, each step, a :class:`~avp_world.types.Beacon`
— its pose, whether it stands waiting, and the path it wants to drive (the plan it drives, or while it waits the plan
it is blocked on, :attr:`~avp_motion.planner_types.Decision.wanted`). The fleet's channel gives an ego the
beacons of the egos that entered before it (their right of way: first in, first served) as they were one step
before (:attr:`~avp_world.types.Observation.beacons`). With one ego there are none, and nothing changes.

After the ego has stood ``ego_yield_after`` s, if a beacon says its sender stands waiting and the first
``ego_yield_clear`` m of its announced path (its footprint along it, grown by the vehicle margin) overlap the ego's
footprint, the ego is in that car's way. If the ego sees the sender (an observed vehicle within ``MATCH`` m of the
beacon's pose), it drives the shortest short manoeuvre of :mod:`.making_way` that ends clear of those footprints and
meets no prediction, then stands aside until that car has left its place by 1 m, or for ``ego_yield_hold`` s at
most (the trace's mode ``make_way``, then cause ``making_way``).

The paper's sentence it departs from: §V-D-3 "the ego would stay put at the current position". On by default (it
acts only in a fleet); the protocol ``paper`` and ``--ablation`` (``no_ego_yield``) switch it off.
"""

from __future__ import annotations

import math
import time

import numpy as np

from avp_collision.reactive import rect_gaps
from avp_motion.making_way import RETRY_STEPS
from avp_motion.planner_types import _Plan
from avp_world.types import Beacon

MATCH = 1.0  # m: an observed vehicle this close to a beacon's pose is its sender
ZONE_STEP = 1.0  # m of announced path between two of its footprints


def path_zones(path: np.ndarray, length: float, width: float, reach: float, margin: float) -> list[tuple]:
    """The footprints (centre pose, half length, half width) of a car of ``length`` x ``width`` along the first
    ``reach`` m of ``path`` (N, 3), one every ``ZONE_STEP`` m and at both ends, grown by ``margin`` a side."""
    p = np.asarray(path, dtype=float).reshape(-1, 3)
    if not len(p):
        return []
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p[:, :2], axis=0).T))])
    keep, last = [0], 0.0
    for i in range(1, len(p)):
        if arc[i] > reach + 1e-9:
            break
        if arc[i] - last >= ZONE_STEP - 1e-9:
            keep.append(i)
            last = arc[i]
    end = int(np.searchsorted(arc, reach + 1e-9, side="right")) - 1
    if end > keep[-1]:
        keep.append(end)
    return [(p[i].copy(), 0.5 * length + margin, 0.5 * width + margin) for i in keep]


class EgoYieldMixin:
    """Methods of :class:`~avp_planner.core.decision.EgoPlanner`; see the module docstring."""

    def _sender_seen(self, obs, b: Beacon):
        """The observed vehicle that sent beacon ``b`` (the nearest within ``MATCH`` m of its pose), or None."""
        best, dist = None, MATCH
        for v in obs.vehicles:
            q = np.asarray(v.history, dtype=float).reshape(-1, 3)[-1]
            r = math.hypot(*(q[:2] - np.asarray(b.pose, dtype=float)[:2]))
            if r <= dist:
                best, dist = v, r
        return best

    def _in_the_way_of(self, obs, ego: np.ndarray) -> list[tuple]:
        """(observed sender, its zones) of every beacon whose sender stands waiting with the ego's footprint on the
        first ``ego_yield_clear`` m of its announced path, and is seen."""
        d, c = self.settings.decision, self.settings.collision
        hl, hw = 0.5 * obs.ego_length, 0.5 * obs.ego_width
        out = []
        for b in obs.beacons:
            if not b.waiting or not len(b.path):
                continue
            v = self._sender_seen(obs, b)
            if v is None:
                continue
            zones = path_zones(b.path, float(v.length), float(v.width), d.ego_yield_clear, c.vehicle_margin)
            zc = np.array([z[0] for z in zones])
            if (rect_gaps(ego[None], zc, hl, hw, np.array([z[1] for z in zones]),
                          np.array([z[2] for z in zones])) < 0.0).any():
                out.append((v, zones))
        return out

    def _yield_to_ego(self, st) -> _Plan | None:
        """Once stood ``ego_yield_after`` s: the shortest manoeuvre out of the announced path of every ego with the
        right of way that waits with the ego in its way (see the module docstring), or None."""
        d, k = self.settings.decision, self.settings.control
        obs = st.obs
        if (not d.ego_yield or not obs.beacons or self._stuck_steps * k.dt < d.ego_yield_after - 1e-9
                or obs.step < self._make_way_retry):
            return None
        t0 = time.perf_counter()
        ways = self._in_the_way_of(obs, st.ego)
        plan = None
        if ways:
            plan = self._way_out_of(st.ego, obs, st, [z for _, zones in ways for z in zones])
            if plan is None:
                self._make_way_retry = obs.step + RETRY_STEPS
        st.timing["spot_selection_time"] += time.perf_counter() - t0
        if plan is not None:
            self._make_way_for = [((False, int(v.id)), np.asarray(v.history, dtype=float).reshape(-1, 3)[-1, :2])
                                  for v, _ in ways]
            self._make_way_until = obs.step + len(plan.traj.controls) + int(round(d.ego_yield_hold / k.dt))
            ids = ", ".join(str(int(v.id)) for v, _ in ways)
            plan.note = f"yielding to car {ids}: an ego with the right of way waits to drive here (ego_yield)"
        return plan


#: poses of an announced path at most (20 s of a plan at dt = 0.1 s): a beacon stays small
MAX_BEACON_POSES = 200  # avp_common.conversions.MAX_BEACON_POSES bounds a received one


def announcement(decision) -> tuple[bool, np.ndarray]:
    """(whether it stands waiting, the path it wants) of a decision: it stands idle or waiting
    (:func:`~avp_motion.trace.step_of`), and the path is its plan's poses, or while waiting the plan it is
    blocked on (:attr:`Decision.wanted <avp_motion.planner_types.Decision.wanted>`), at most
    ``MAX_BEACON_POSES``. A decision without these fields (a plugin's) announces a path of its poses."""
    from avp_motion.trace import step_of

    waiting = bool(step_of(decision)[2]) if hasattr(decision, "command") else False
    path = getattr(decision, "wanted", None) if waiting else getattr(decision, "poses", None)
    path = np.zeros((0, 3)) if path is None else np.asarray(path, dtype=float).reshape(-1, 3)
    return waiting, path[:MAX_BEACON_POSES].copy()


def beacon_of(ego: int, pose, decision) -> Beacon:
    """What ego ``ego`` announces after deciding ``decision`` at ``pose`` (:func:`announcement`)."""
    waiting, path = announcement(decision)
    return Beacon(int(ego), np.asarray(pose, dtype=float).reshape(3).copy(), waiting, path)


def heard_by(beacons, ego: int) -> tuple[Beacon, ...]:
    """The fleet channel's rule: ego ``ego`` hears the beacons of the egos that entered before it (lower index:
    first in, first served), in index order."""
    return tuple(sorted((b for b in beacons if b.ego < ego), key=lambda b: b.ego))


def with_beacons(obs, beacons, ego: int):
    """``obs`` of ego ``ego`` as the in-process channel hands it over: with the beacons it hears (:func:`heard_by`)
    of those sent the step before; ``obs`` itself if it hears none."""
    from dataclasses import replace

    heard = heard_by(beacons, ego)
    return replace(obs, beacons=heard) if heard else obs

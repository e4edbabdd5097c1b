"""Agents that keep clear of each other (``agents_yield``; a departure from §III-B, off by default).

§III-B's reactive agent brakes when its next n_pass planned footprints meet the **ego's** current footprint; nothing
makes it stop for another agent. On the paper's lot, with one or two moving cars and no pedestrians, they do not meet.
On the busy lot they do: a car that stops for the ego is driven into by the cars behind it, and cars drive through
pedestrians (tools/agent_overlaps.py, docs/research/unfreezing.md).

With ``agents_yield`` the same rule applies between the agents, with the same look-ahead n_pass (so non-reactive
agents, n_pass = 0, still follow their plans whatever happens). Agent i's next n_pass planned footprints are checked
against agent k now (k **in the way**) and against k's own plan at the same steps (the two **crossing**: both in
motion, closing on one place, which a check against the present misses):

* a moving car brakes for a car in its way (moving or parked) and for a pedestrian in its way or crossing;
* a pedestrian stops for a moving car in its way;
* of two cars crossing, the one that comes later in the scenario brakes, unless the other already brakes for it.

Agents that would each wait for the other would stand for good, so the rule keeps them live:

* a pair that overlaps already is left alone (braking cannot part it; a queue outside the gate starts so), but for a
  car touching a pedestrian on its way: the car waits, the pedestrian walks on and they part;
* of two cars each in the other's way (head-on in one lane), the first in the scenario drives on;
* of a car and a pedestrian each in the other's way, the pedestrian walks on and the car waits.

The rule does not steer: a car never goes round another, so a head-on in one lane still ends overlapping.

Braking for another agent is not braking for the ego: it is kept apart (``World.yielding``) and does not count in the
§VI-B interrupted-steps metric.
"""

from __future__ import annotations

import numpy as np

from avp_world.geometry import disc_rect_overlap, rect_corners, rects_overlap
from avp_world.kinematics import step_pedestrian, step_vehicle


def plan_lookahead(states, plans, rows, index, steps, step_fn, dt) -> np.ndarray:
    """(len(rows), steps, state): agents ``rows`` rolled out from ``states`` with their next ``steps`` unused planned
    controls of ``plans`` (from ``index`` on; the last control repeats past a plan's end). Shared with §III-B's rule
    in :meth:`World._reactive_brakes`."""
    out = np.zeros((len(rows), steps, states.shape[1]))
    s = states
    for j in range(steps):
        s = step_fn(s, plans[rows, np.minimum(index + j, plans.shape[1] - 1)], dt)
        out[:, j] = s
    return out


def agents_yield(w) -> tuple[np.ndarray, np.ndarray]:
    """(vehicles that brake, pedestrians that stop) for each other at this step of World ``w`` (module docstring).

    An agent's next n_pass planned footprints are checked against where the other agent is now **and** where the
    other's plan puts it at the same step: two agents closing on one point both in motion meet in the second.
    """
    n, p = len(w.states), len(w.ped_pos)
    v_brake, p_stop = np.zeros(n, dtype=bool), np.zeros(p, dtype=bool)
    steps = int(max(w.passiveness.max(initial=0), w.ped_pass.max(initial=0)))
    moving = np.nonzero(w.is_dynamic)[0]
    if steps == 0 or not len(moving):
        return v_brake, p_stop
    corners = rect_corners(w.states, w.vehicle_dims[:, 0], w.vehicle_dims[:, 1])
    fut = np.repeat(corners[:, None], steps, axis=1)  # (n, L, 4, 2): parked cars stay where they are
    ahead = plan_lookahead(w.states[moving], w.plans, moving, w.plan_index[moving], steps, step_vehicle, w.dt)
    fut[moving] = rect_corners(ahead, w.vehicle_dims[moving, 0, None], w.vehicle_dims[moving, 1, None])
    v_valid = np.arange(steps)[None] < w.passiveness[:, None]  # (n, L): each car looks n_pass steps ahead
    ped_fut = (plan_lookahead(w.ped_pos, w.ped_plans, np.arange(p), w.ped_index, steps, step_pedestrian, w.dt)
               if p else None)
    p_valid = np.arange(steps)[None] < w.ped_pass[:, None]
    car_meets_ped = np.zeros((n, p), dtype=bool)
    movers = np.nonzero(w.is_dynamic & (w.passiveness > 0))[0]
    if len(movers):
        reach = 2.0 * w._brake_reach[movers] + np.hypot(*w.vehicle_dims.max(axis=0, initial=0.0))
        gap = np.hypot(*(w.states[movers, None, :2] - w.states[None, :, :2]).transpose(2, 0, 1))
        a, k = np.nonzero(gap <= reach[:, None])
        i = movers[a]
        keep = i != k
        i, k = i[keep], k[keep]
        keep = ~rects_overlap(corners[i], corners[k])  # overlapping already: braking cannot part them
        i, k = i[keep], k[keep]
        valid = v_valid[i]
        way = (rects_overlap(fut[i], corners[k][:, None]) & valid).any(axis=1)
        cross = ~way & (rects_overlap(fut[i], fut[k]) & valid).any(axis=1)
        in_way = set(zip(i[way].tolist(), k[way].tolist(), strict=True))  # k is now where i's next steps go
        crossing = set(zip(i[cross].tolist(), k[cross].tolist(), strict=True))  # both planned onto one place
        for i, k in in_way:  # of two each in the other's way (head-on), the first in the scenario drives on
            if not ((k, i) in in_way and i < k):
                v_brake[i] = True
        for i, k in crossing:  # k already waits for i, or goes first as the first in the scenario
            if (k, i) not in in_way and i > k:
                v_brake[i] = True
        if p:  # cars wait for pedestrians on their way (also one they touch: it walks on, they part): (m, L, P)
            fm = fut[movers][:, :, None]
            hit = (disc_rect_overlap(w.ped_pos[None, None], w.ped_radii[None, None], fm)
                   | disc_rect_overlap(ped_fut.transpose(1, 0, 2)[None], w.ped_radii[None, None], fm))
            car_meets_ped[movers] = (hit & v_valid[movers][:, :, None]).any(axis=1)
            v_brake[movers] |= car_meets_ped[movers].any(axis=1)
    walkers = np.nonzero(w.ped_pass > 0)[0]
    if len(walkers):  # pedestrians wait for moving cars, unless that car waits for them: (m, L, M)
        r = w.ped_radii[walkers]
        now = disc_rect_overlap(w.ped_pos[walkers, None], r[:, None], corners[None, moving])  # (m, M)
        pf = ped_fut[walkers][:, :, None]
        hit = (disc_rect_overlap(pf, r[:, None, None], corners[None, None, moving])
               | disc_rect_overlap(pf, r[:, None, None], fut[moving].transpose(1, 0, 2, 3)[None]))
        meets_car = (hit & p_valid[walkers][:, :, None]).any(axis=1) & ~now & ~car_meets_ped[moving][:, walkers].T
        p_stop[walkers] = meets_car.any(axis=1)
    return v_brake, p_stop

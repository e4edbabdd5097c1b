"""The several-egos metrics that need more than one ego's record, from plain arrays: who lies in which spot, the
spots each ego loses, and the waits-for edges of the gridlock metric (docs/metrics.md, "Several egos").

The in-process fleet (:mod:`.fleet`) feeds them from the world; the DDS transport's collector
(:mod:`.ros_fleet_collector`) from ``debug/ground_truth``, ``debug/braking_for`` and each ego's planner decisions
and decision traces, so both give the same numbers.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from avp_episode.gridlock import Node


def spot_holders(lot, agent_corners: np.ndarray, ego_corners: np.ndarray, ego_ids: Iterable[int]) -> dict[int, str]:
    """Spot id -> ``"agent"`` or ``"ego:<j>"`` for every spot a vehicle or ego lies inside (§III-A's rule).
    ``agent_corners`` (N, 4, 2) of the agents' vehicles, ``ego_corners`` (M, 4, 2) of the egos in the lot, whose
    indices are ``ego_ids``."""
    from avp_sensing.occupancy import classify_world

    ego_ids = [int(j) for j in ego_ids]
    corners = np.concatenate([agent_corners, ego_corners]) if len(ego_ids) else agent_corners
    _, vehicle_spot = classify_world(lot, corners)
    return holders_of(lot, vehicle_spot, len(agent_corners), ego_ids)


def holders_of(lot, vehicle_spot: np.ndarray, n_agents: int, ego_ids: Iterable[int]) -> dict[int, str]:
    """:func:`spot_holders` from the classification (:func:`~avp_sensing.occupancy.classify_world`'s
    ``vehicle_spot``) of the ``n_agents`` agents and then the egos ``ego_ids``."""
    ego_ids = [int(j) for j in ego_ids]
    out: dict[int, str] = {}
    for r, row in enumerate(vehicle_spot):
        if row >= 0:
            out[int(lot.spot_ids[row])] = "agent" if r < n_agents else f"ego:{ego_ids[r - n_agents]}"
    return out


class SpotLosses:
    """Each ego's spots *lost*: the spot it is driving to park in (its decision's target, taken when the spot was
    free) taken by another vehicle — an agent or another ego that comes to lie inside it — before it parks there."""

    def __init__(self, k: int):
        self.target = [-1] * k
        self.lost = [{"agent": 0, "ego": 0} for _ in range(k)]

    def decided(self, ego: int, parking: bool, spot: int, holders: Mapping[int, str]) -> None:
        """Ego ``ego`` decided this step (``holders``: the spots' holders before the step). A spot another vehicle
        already lies in is no spot to lose: only a free one becomes the target."""
        if parking and holders.get(int(spot)) in (None, f"ego:{ego}"):
            self.target[ego] = int(spot)

    def stepped(self, holders: Mapping[int, str]) -> None:
        """The holders after the step: a target now held by another vehicle is lost."""
        for i, spot in enumerate(self.target):
            who = holders.get(spot)
            if spot >= 0 and who is not None and who != f"ego:{i}":
                self.lost[i]["agent" if who == "agent" else "ego"] += 1
                self.target[i] = -1


def wait_edges(ego_waits: Iterable[tuple[int, int]], braking_for: Iterable[tuple[int, int]],
               ego_id_base: int) -> dict[Node, set[Node]]:
    """One step's waits-for edges (:mod:`.gridlock`). ``ego_waits``: (ego i, the agent id its trace names) for each
    ego that stands or waits for a vehicle (another ego is named by its observed id ``ego_id_base + j``);
    ``braking_for``: (agent id, ego j) for each agent that brakes for an ego."""
    edges: dict[Node, set[Node]] = {}
    for i, a in ego_waits:
        edges.setdefault(("ego", int(i)), set()).add(("ego", a - ego_id_base) if a >= ego_id_base else ("agent", a))
    for a, j in braking_for:
        edges.setdefault(("agent", int(a)), set()).add(("ego", int(j)))
    return edges


def trace_wait(still: bool, agent_id: int | None, pedestrian: bool) -> int | None:
    """The vehicle an ego's step waits for (its trace's blocking agent while it stands or waits), or None."""
    if still and agent_id is not None and int(agent_id) >= 0 and not pedestrian:
        return int(agent_id)
    return None

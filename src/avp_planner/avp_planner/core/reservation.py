"""Spot reservations among several egos: the centralised reference of docs/world.md ("Several egos"), as the oracle
is for one ego. Not in the paper (one ego); a message between egos, stated as such.

First come, first served: an ego claims the spot it is about to park in; the claim is granted when no other ego holds
that spot, and refused otherwise. An ego holds at most one spot: a new claim releases its old one. A hold ends when
the ego parks, gives up the spot (its decision targets another spot, or it explores), leaves the episode, or has not
been heard from for ``timeout`` (a dead pipeline's spot goes back to the pool). The method profile ``reserve``
(avp_episode/config/methods/reserve.yaml) plans only to spots it holds or that nobody holds: the spots other egos
hold are shown to its pipeline as occupied (:meth:`SpotReservations.apply`). Every ego plans a step with the holds
as they stood after the step before (:meth:`SpotReservations.settle`), in process and in the live graph
(avp_planner.reservation_node).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from avp_world.types import Observation


@dataclass
class Hold:
    ego: int
    spot: int
    since: float  # time of the grant
    heard: float  # time the ego was last heard from


class SpotReservations:
    """The book of holds. Times are seconds of any clock the caller keeps (simulated time in process)."""

    def __init__(self, timeout: float = 5.0):
        if not timeout > 0:
            raise ValueError(f"reservation timeout must be > 0 s, got {timeout}")
        self.timeout = float(timeout)
        self.by_ego: dict[int, Hold] = {}
        self.refused = 0  # claims refused so far

    def holder(self, spot: int) -> int | None:
        """The ego that holds ``spot``, or None."""
        return next((h.ego for h in self.by_ego.values() if h.spot == spot), None)

    def held_by_others(self, ego: int) -> set[int]:
        return {h.spot for h in self.by_ego.values() if h.ego != ego}

    def claim(self, ego: int, spot: int, now: float) -> bool:
        """Grant ``spot`` to ``ego`` (releasing its other hold) unless another ego holds it."""
        self.expire(now)
        other = self.holder(spot)
        if other is not None and other != ego:
            self.refused += 1
            self.heartbeat(ego, now)
            return False
        held = self.by_ego.get(ego)
        since = held.since if held is not None and held.spot == spot else now
        self.by_ego[ego] = Hold(ego, int(spot), since, now)
        return True

    def heartbeat(self, ego: int, now: float) -> None:
        """The ego answered (its hold, if any, stays)."""
        if ego in self.by_ego:
            self.by_ego[ego].heard = now

    def release(self, ego: int) -> int | None:
        """End ``ego``'s hold; the spot it held, or None."""
        h = self.by_ego.pop(ego, None)
        return None if h is None else h.spot

    def expire(self, now: float) -> list[int]:
        """Release the holds of egos not heard from for ``timeout``; the egos released."""
        dead = [e for e, h in self.by_ego.items() if now - h.heard > self.timeout + 1e-9]
        for e in dead:
            self.by_ego.pop(e)
        return dead

    def update(self, ego: int, decision, now: float) -> None:
        """After ``ego``'s decision: claim the spot it parks to; release its hold when it targets none (it explores,
        or parks elsewhere); keep it while it waits (idle)."""
        mode = getattr(decision, "mode", None)
        if mode == "park" and int(decision.spot_id) >= 0:
            self.claim(ego, int(decision.spot_id), now)
        elif mode == "explore":
            self.release(ego)
        else:
            self.heartbeat(ego, now)

    def apply(self, obs: Observation, ego: int) -> Observation:
        """``obs`` with the spots other egos hold moved from vacant to occupied (what ``reserve`` plans with)."""
        moved = self.hide(obs.vacant_spot_ids, obs.occupied_spot_ids, ego)
        return obs if moved is None else dataclasses.replace(obs, vacant_spot_ids=moved[0], occupied_spot_ids=moved[1])

    def hide(self, vacant, occupied, ego: int) -> tuple[np.ndarray, np.ndarray] | None:
        """(vacant, occupied) spot ids with the spots other egos hold moved from the first to the end of the second,
        or None when no vacant spot is held (an Observation's or an avp_msgs/Observation's id lists)."""
        held = self.held_by_others(ego)
        if not held:
            return None
        vac = np.asarray(vacant, dtype=np.int64)
        taken = np.isin(vac, np.fromiter(held, dtype=np.int64))
        if not taken.any():
            return None
        return vac[~taken], np.concatenate([np.asarray(occupied, dtype=np.int64), vac[taken]])

    def settle(self, decisions: dict[int, object], now: float) -> None:
        """One step's decisions of the egos that use the book, applied in ego order after all of them decided (each
        ego plans a step with the holds as they stood after the step before; a live graph can wait for exactly
        that, whatever order the egos' messages arrive in)."""
        for ego in sorted(decisions):
            self.update(ego, decisions[ego], now)

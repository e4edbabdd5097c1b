"""reservation node: the spot-reservation book of several egos in the live graph (docs/world.md, "Several egos").

The centralised reference of the method profile ``reserve``, as the oracle is for one ego: a message between the egos,
not something an ego observes. It sits between the simulator and each ``reserve`` ego's pipeline
(avp_bringup.graph.fleet_graph remaps that pipeline's ``observation`` to ``reserved/observation``):

  subscribes  ego<i>/observation (tagged by the simulator with ego i's key), ego<i>/decision (ego i's planner),
              ego<i>/episode_status, for each ego i of parameter ``egos``
  publishes   ego<i>/reserved/observation: the observation with the spots other egos hold moved from vacant to
              occupied (:meth:`avp_planner.core.reservation.SpotReservations.hide`), tagged with ego i's key

Each ego plans step k with the holds as they stood after step k-1 (:meth:`SpotReservations.settle`), relayed in
lock-step as :mod:`avp_planner.lockstep_relay` says; lock-step also waits for each ego's status of step k (a hold
ends when its ego parks, crashes or times out). In real time it forwards at once, with the book as it stands. A hold
also ends when its ego has not decided for ``timeout`` s of simulated time.
"""

from __future__ import annotations

import sys

from avp_common.node_main import run_node
from avp_common.params import ParamSpec
from avp_msgs.msg import EpisodeStatus, Observation, PlannerDecision
from avp_planner.core.reservation import SpotReservations
from avp_planner.lockstep_relay import RELAY_PARAMS, LockstepRelay

RESERVATION_PARAMS = [
    ParamSpec("egos", str, "Indices of the egos that plan with the book (those running the profile reserve), "
              "comma-separated.", default="0,1"),
    ParamSpec("min_subscribers", int, "Forward an ego's first observation once its reserved/observation has this "
              "many subscribers (its pipeline's belief, prediction and planner nodes).", min=0, default=3),
    ParamSpec("timeout", float, "A hold ends when its ego has not decided for this long [s, simulated time].",
              min=0.1, default=5.0),
    RELAY_PARAMS[2],  # lockstep
]
_RUNNING = (EpisodeStatus.STATE_IDLE, EpisodeStatus.STATE_RUNNING)


class _Decided:
    """What the book needs of a decision (the fields :meth:`SpotReservations.update` reads)."""

    def __init__(self, msg: PlannerDecision):
        self.mode = {PlannerDecision.MODE_PARK: "park", PlannerDecision.MODE_EXPLORE: "explore"}.get(msg.mode, "idle")
        self.spot_id = int(msg.spot_id)


class ReservationNode(LockstepRelay):
    output = "reserved/observation"
    needs_status = True

    def __init__(self) -> None:
        super().__init__("avp_reservation", RESERVATION_PARAMS)

    def reset(self) -> None:
        self.book = SpotReservations(float(self.params["timeout"]))

    def settle(self, step: int, decided: dict[int, PlannerDecision], now: float) -> None:
        """The holds after ``step``: its decisions in ego order, then the ends (episodes over, egos silent)."""
        self.book.settle({i: _Decided(m) for i, m in decided.items()}, now)
        for i, (_, state) in self.status.items():
            if state not in _RUNNING:
                self.book.release(i)
        self.book.expire(now)

    def transform(self, i: int, msg: Observation) -> Observation:
        moved = self.book.hide(msg.vacant_spot_ids, msg.occupied_spot_ids, i)
        if moved is not None:
            msg.vacant_spot_ids = [int(x) for x in moved[0]]
            msg.occupied_spot_ids = [int(x) for x in moved[1]]
        return msg


def main(args=None) -> int:
    return run_node(ReservationNode, "avp_reservation", args)


if __name__ == "__main__":
    sys.exit(main())

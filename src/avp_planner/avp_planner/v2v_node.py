"""v2v node: the radio between the egos of a fleet in the live graph (docs/world.md, "Several egos").

Every ego of a fleet announces, each step, a beacon (avp_msgs/EgoBeacon, :mod:`avp_planner.core.ego_yield`): its
pose, whether it stands waiting, and the path it wants to drive — the fields ``waiting`` and ``announced`` of its
planner's decision. This node is the channel: a message between the egos, not something an ego observes. It sits
between the simulator (or, for a ``reserve`` ego, the reservation node) and each ego's pipeline
(avp_bringup.graph.fleet_graph remaps that pipeline's ``observation`` to ``v2v/observation``):

  subscribes  ego<i>/observation (ego<i>/reserved/observation for the egos of ``reserve_egos``), ego<i>/decision,
              ego<i>/episode_status, for each ego i of parameter ``egos``
  publishes   ego<i>/v2v/observation: the observation with ``beacons`` set to those of the egos that entered before
              ego i (:func:`~avp_planner.core.ego_yield.heard_by`), as they decided the step before, tagged with
              ego i's key

Relayed in lock-step as :mod:`avp_planner.lockstep_relay` says, so the same seed gives the in-process fleet's episode
(:func:`avp_experiment.fleet.run_fleet_inproc` hands the beacons over the same way). A beacon's pose is the sender's
observed pose of the step it decided; its path is at most ``MAX_BEACON_POSES`` poses (a receiver refuses a longer one,
avp_common.conversions).
"""

from __future__ import annotations

import sys

from geometry_msgs.msg import Pose2D

from avp_common.node_main import run_node
from avp_common.params import ParamSpec
from avp_msgs.msg import EgoBeacon, Observation, PlannerDecision
from avp_planner.core.ego_yield import MAX_BEACON_POSES
from avp_planner.lockstep_relay import RELAY_PARAMS, LockstepRelay, parse_egos

V2V_PARAMS = [
    ParamSpec("egos", str, "Indices of the fleet's egos (every one), comma-separated.", default="0,1"),
    ParamSpec("reserve_egos", str, "Those of them whose observation comes from the reservation node "
              "(ego<i>/reserved/observation), comma-separated; empty: none.", default=""),
    RELAY_PARAMS[1],  # min_subscribers
    RELAY_PARAMS[2],  # lockstep
]


class V2VNode(LockstepRelay):
    output = "v2v/observation"

    def __init__(self) -> None:
        super().__init__("avp_v2v", V2V_PARAMS)

    def source(self, i: int) -> str:
        reserve = parse_egos(self.params["reserve_egos"], "reserve_egos")
        return f"ego{i}/reserved/observation" if i in reserve else f"ego{i}/observation"

    def reset(self) -> None:
        self.beacons: list[EgoBeacon] = []  # what the egos announced at the step last settled, in ego order

    def settle(self, step: int, decided: dict[int, PlannerDecision], now: float) -> None:
        """The beacons of ``step``: each ego that decided it, at the pose of the observation it decided on."""
        beacons = []
        for i, m in decided.items():
            if i not in self.sent or self.sent[i][0] != step:
                continue
            p = self.sent[i][1].ego_pose
            beacons.append(EgoBeacon(ego=i, pose=Pose2D(x=p.x, y=p.y, theta=p.theta), waiting=bool(m.waiting),
                                     path=list(m.announced[:MAX_BEACON_POSES])))
        self.beacons = beacons

    def transform(self, i: int, msg: Observation) -> Observation:
        msg.beacons = [b for b in self.beacons if b.ego < i]  # first in, first served (ego_yield.heard_by)
        return msg


def main(args=None) -> int:
    return run_node(V2VNode, "avp_v2v", args)


if __name__ == "__main__":
    sys.exit(main())

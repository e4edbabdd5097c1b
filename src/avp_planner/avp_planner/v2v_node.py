"""v2v node: the radio between the egos of a fleet in the live graph (docs/world.md, "Several egos").

Every ego of a fleet announces, each step, a beacon (avp_msgs/EgoBeacon, :mod:`avp_planner.core.ego_yield`): its
pose, whether it stands waiting, and the path it wants to drive — its planner's decision carries ``waiting`` and
``announced``. This node is the channel: a message between the egos, not something an ego observes.

  subscribes  ego<i>/observation (the simulator's: the step and pose it was sent, read from the message's head
              without building the rest, avp_common.received.observation_head), ego<i>/decision,
              ego<i>/episode_status, for each ego i of parameter ``egos``
  publishes   ego<i>/v2v/beacons (avp_msgs/EgoBeaconArray) for each observation k of ego i: the beacons of the egos
              that entered before it (:func:`~avp_planner.core.ego_yield.heard_by`) as they decided step k-1, at
              the pose of the observation each decided on; tagged with ego i's key

The planners of a fleet (``use_beacons``) decide step k once they have its beacons, as they wait for its beliefs and
predictions; the observation itself goes from the simulator to the pipeline untouched. Relayed in lock-step as
:mod:`avp_planner.lockstep_relay` says, so the same seed gives the in-process fleet's episode
(:func:`avp_episode.fleet.run_fleet_inproc` hands the beacons over the same way). A beacon's path is at most
``MAX_BEACON_POSES`` poses (a planner refuses a longer one, avp_common.conversions).
"""

from __future__ import annotations

import sys

from geometry_msgs.msg import Pose2D

from avp_common.msg_auth import episode_of, with_episode
from avp_common.node_main import run_node
from avp_common.params import ParamSpec
from avp_common.received import ObservationHead, observation_head
from avp_msgs.msg import EgoBeacon, EgoBeaconArray, PlannerDecision
from avp_planner.core.ego_yield import MAX_BEACON_POSES
from avp_planner.lockstep_relay import RELAY_PARAMS, LockstepRelay

V2V_PARAMS = [
    ParamSpec("egos", str, "Indices of the fleet's egos (every one), comma-separated.", default="0,1"),
    ParamSpec("min_subscribers", int, "Answer an ego's first observation once its v2v/beacons has this many "
              "subscribers (its planner).", min=0, default=1),
    RELAY_PARAMS[2],  # lockstep
]


class V2VNode(LockstepRelay):
    output = "v2v/beacons"
    output_type = EgoBeaconArray
    #: the step, stamp, episode and ego pose are all it reads of an observation: never the whole message built
    read_input = staticmethod(observation_head)

    def __init__(self) -> None:
        super().__init__("avp_v2v", V2V_PARAMS)

    def reset(self) -> None:
        self.beacons: list[EgoBeacon] = []  # what the egos announced at the step last settled, in ego order
        self.poses: dict[int, tuple[int, Pose2D]] = {}  # ego -> (step, pose) of the newest observation answered

    def settle(self, step: int, decided: dict[int, PlannerDecision], now: float) -> None:
        """The beacons of ``step``: each ego that decided it, at the pose of the observation it decided on."""
        beacons = []
        for i, m in decided.items():
            if self.poses.get(i, (-1, None))[0] != step:
                continue
            p = self.poses[i][1]
            beacons.append(EgoBeacon(ego=i, pose=Pose2D(x=p.x, y=p.y, theta=p.theta), waiting=bool(m.waiting),
                                     path=list(m.announced[:MAX_BEACON_POSES])))
        self.beacons = beacons

    def transform(self, i: int, msg: ObservationHead) -> EgoBeaconArray:
        """What ego i hears for observation ``msg`` (its head): the beacons of the egos before it
        (ego_yield.heard_by)."""
        self.poses[i] = (int(msg.step), msg.ego_pose)
        out = EgoBeaconArray(step=msg.step, beacons=[b for b in self.beacons if b.ego < i])
        out.header.stamp = msg.header.stamp
        out.header.frame_id = with_episode("map", episode_of(msg.header.frame_id))  # tagged anew on publishing
        return out


def main(args=None) -> int:
    return run_node(V2VNode, "avp_v2v", args)


if __name__ == "__main__":
    sys.exit(main())

"""avp_msgs/IntentionArray <-> core :class:`~avp_predictors.intention.Intention` (with validation).

Beliefs and predictions, which the planner reads too, are converted in ``avp_common.conversions``; the
intentions are perception's own (belief node -> prediction node), so their conversion lives here and
avp_common does not depend on avp_perception. Probabilities travel as float32 (the message fields);
``avp_perception.core.pipeline.float32_intention`` applies the same rounding in-process, so an in-process
chain of the cores is bit-identical to the nodes.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from geometry_msgs.msg import Pose2D

from avp_common.conversions import MessageError, check_finite, check_probabilities, step_to_time
from avp_msgs.msg import Intention as IntentionMsg
from avp_msgs.msg import IntentionArray
from avp_predictors.intention import Intention
from avp_world.lot import LotMap


def intentions_to_msg(step: int, dt: float, intentions: Iterable[Intention]) -> IntentionArray:
    """IntentionArray stamped t = step * dt."""
    msg = IntentionArray()
    msg.header.frame_id = "map"
    msg.header.stamp = step_to_time(step, dt)
    msg.step = int(step)
    for it in intentions:
        m = IntentionMsg(vehicle_id=int(it.vehicle_id), none_probability=float(it.none_probability))
        m.spot_ids = [int(i) for i in it.spot_ids]
        m.spot_probabilities = np.asarray(it.spot_probabilities, dtype=np.float32)
        m.exploration_points = [Pose2D(x=float(q[0]), y=float(q[1]), theta=float(q[2]))
                                for q in np.asarray(it.exploration_points, dtype=float).reshape(-1, 3)]
        m.exploration_probabilities = np.asarray(it.exploration_probabilities, dtype=np.float32)
        msg.intentions.append(m)
    return msg


def intentions_from_msg(msg: IntentionArray, lot: LotMap | None = None) -> list[Intention]:
    """Core intentions; MessageError for NaN/inf, probabilities outside [0, 1], array sizes that differ, a
    vehicle listed twice or (given ``lot``) an unknown spot id."""
    out = []
    seen: set[int] = set()
    for m in msg.intentions:
        vid = int(m.vehicle_id)
        what = f"intention of vehicle {vid}"
        if vid in seen:
            raise MessageError(f"{what}: vehicle listed twice")
        seen.add(vid)
        if len(m.spot_ids) != len(m.spot_probabilities):
            raise MessageError(f"{what}: {len(m.spot_ids)} spot ids but {len(m.spot_probabilities)} probabilities")
        if len(m.exploration_points) != len(m.exploration_probabilities):
            raise MessageError(f"{what}: {len(m.exploration_points)} exploration points but "
                               f"{len(m.exploration_probabilities)} probabilities")
        ids = np.asarray(m.spot_ids, dtype=np.int64)
        if lot is not None:
            unknown = [int(i) for i in ids if not lot.has_spot(int(i))]
            if unknown:
                raise MessageError(f"{what}: unknown spot id {unknown[0]}")
        pts = np.array([[q.x, q.y, q.theta] for q in m.exploration_points], dtype=float).reshape(-1, 3)
        check_finite(pts, f"{what}: exploration_points")
        out.append(Intention(
            vehicle_id=vid,
            spot_ids=ids,
            spot_probabilities=check_probabilities(m.spot_probabilities, f"{what}: spot_probabilities"),
            exploration_points=pts,
            exploration_probabilities=check_probabilities(m.exploration_probabilities,
                                                          f"{what}: exploration_probabilities"),
            none_probability=float(check_probabilities([m.none_probability], f"{what}: none_probability")[0]),
        ))
    return out

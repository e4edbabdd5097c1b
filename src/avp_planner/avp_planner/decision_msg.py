"""The planner node's messages of a decision (§V-D): its plan (nav_msgs/Path), the avp_msgs/PlannerDecision and the
plan's markers; and the one input of the "Implicit" method that is more than a conversion (the ego's own intention).

Plain functions of a :class:`~avp_motion.planner_types.Decision` and message fields, no node: the node
(:mod:`avp_planner.planner_node`) publishes what they build. The decision trace has its own module
(:mod:`avp_planner.trace_msg`).
"""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from avp_common.conversions import MessageError, check_probabilities, poses_to_msg
from avp_common.markers import quat_z
from avp_common.msg_auth import with_episode
from avp_msgs.msg import IntentionArray, PlannerDecision
from avp_planner.core.ego_yield import announcement

#: the core's modes as PlannerDecision's constants
MODES = {"idle": PlannerDecision.MODE_IDLE, "park": PlannerDecision.MODE_PARK, "explore": PlannerDecision.MODE_EXPLORE}
#: the most poses a published plan holds (a longer one is thinned evenly)
MAX_PLAN_POSES = 200


def ego_priority_from_msg(msg: IntentionArray, lot) -> np.ndarray:
    """The spot order of the "Implicit" method from an ego_intention message (one Intention: spot ids and
    float32 eta_0,i): decreasing probability, ties smaller id first. MessageError for anything but exactly one
    intention, sizes that differ, NaN/inf or probabilities outside [0, 1], unknown spot ids."""
    from avp_world.types import priority_from_probabilities

    if len(msg.intentions) != 1:
        raise MessageError(f"expected exactly one intention (the ego's), got {len(msg.intentions)}")
    m = msg.intentions[0]
    if len(m.spot_ids) != len(m.spot_probabilities):
        raise MessageError(f"{len(m.spot_ids)} spot ids but {len(m.spot_probabilities)} probabilities")
    ids = np.asarray(m.spot_ids, dtype=np.int64)
    unknown = [int(i) for i in ids if not lot.has_spot(int(i))]
    if unknown:
        raise MessageError(f"unknown spot id {unknown[0]}")
    p = check_probabilities(m.spot_probabilities, "spot_probabilities")
    return priority_from_probabilities(ids, p)


def plan_msg(stamp, poses) -> Path:
    """The plan's (N, 3) ``poses`` (x, y, theta; None: no plan) as a Path in ``map``, stamped like the observation it
    answers; at most :data:`MAX_PLAN_POSES` of them, evenly spaced."""
    path = Path()
    path.header.stamp = stamp
    path.header.frame_id = "map"
    poses = np.asarray(poses if poses is not None else np.zeros((0, 3)))
    for q in poses[:: max(1, len(poses) // MAX_PLAN_POSES)] if len(poses) else []:
        ps = PoseStamped()
        ps.header = path.header
        ps.pose.position.x, ps.pose.position.y = float(q[0]), float(q[1])
        ps.pose.orientation.z, ps.pose.orientation.w = quat_z(float(q[2]))
        path.poses.append(ps)
    return path


def decision_msg(d, path: Path, step: int, episode: int, total: float) -> PlannerDecision:
    """The PlannerDecision of the core's decision ``d`` for observation ``step`` of ``episode``: mode, spot, goal, the
    plan ``path``, the candidate count and timings (``total``: the decision's wall seconds, the path-planning time
    when the core reports none), its reason, and what a fleet's V2V channel turns into this ego's beacon."""
    msg = PlannerDecision()
    msg.header = Header(stamp=path.header.stamp, frame_id=with_episode("map", episode))  # tagged when published
    msg.step = int(step)
    msg.mode = MODES.get(d.mode, PlannerDecision.MODE_IDLE)
    msg.spot_id = int(d.spot_id)
    goal = getattr(d, "goal", None)
    if goal is not None and len(goal) == 3:
        msg.goal.x, msg.goal.y, msg.goal.theta = (float(x) for x in goal)
    msg.plan = path
    msg.n_candidates = int(getattr(d, "n_candidates", 0))
    timings = getattr(d, "timings", {}) or {}
    msg.spot_selection_time = float(timings.get("spot_selection_time", 0.0))
    msg.path_planning_time = float(timings.get("path_planning_time", total))
    msg.reason = str(getattr(d, "reason", ""))
    waiting, announced = announcement(d)  # avp_planner.v2v_node
    msg.waiting, msg.announced = waiting, poses_to_msg(announced)
    return msg


def plan_markers(path: Path, d: PlannerDecision) -> MarkerArray:
    """The plan (line strip, green when parking, blue when exploring) and its goal (arrow)."""
    arr = MarkerArray()
    clear = Marker()
    clear.action = Marker.DELETEALL
    arr.markers.append(clear)
    color = ColorRGBA(r=0.1, g=0.8, b=0.2, a=0.9) if d.mode == PlannerDecision.MODE_PARK else ColorRGBA(
        r=0.2, g=0.4, b=1.0, a=0.9)
    line = Marker(ns="plan", id=0, type=Marker.LINE_STRIP, action=Marker.ADD, color=color)
    line.header = path.header
    line.scale.x = 0.15
    line.points = [ps.pose.position for ps in path.poses]
    arr.markers.append(line)
    if d.mode != PlannerDecision.MODE_IDLE:
        goal = Marker(ns="goal", id=0, type=Marker.ARROW, action=Marker.ADD, color=color)
        goal.header = path.header
        goal.pose.position.x, goal.pose.position.y = d.goal.x, d.goal.y
        goal.pose.orientation.z, goal.pose.orientation.w = quat_z(d.goal.theta)
        goal.scale.x, goal.scale.y, goal.scale.z = 2.0, 0.4, 0.4
        arr.markers.append(goal)
    return arr

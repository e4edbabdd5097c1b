"""The 3-D scene a viewer (Foxglove, Lichtblick, RViz) shows of one step, built from what the ego knows.

Frames (REP-105): ``map`` (the lot), ``odom`` (= ``map``: the simulated ego localises perfectly, so ``map -> odom``
is a static identity on ``/tf_static``), ``base_link`` (the ego, ``odom -> base_link`` on ``/tf``) and
``agent_<id>`` (every vehicle the ego observes, ``map -> agent_<id>``). The markers (``visualization_msgs``,
frame ``map``) show the ego's view, not the ground truth, on three topics so that what does not change is not
sent again every step: ``viz/lot`` (latched, once per lot: boundary and spot outlines), ``viz/spots`` (latched,
whenever a spot's colour changes: the spots filled by the belief b_t of eq. 8, green vacant 0 -> red occupied 1,
grey never observed) and ``viz/scene`` (every step: the observed vehicles' footprints, static blue, moving
yellow, pedestrians white, each predicted trajectory of §V-C in magenta with its probability as opacity, the
ego, its planned path of §V-D, green parking, blue exploring, and the chosen spot's outline). Everything is
stamped with the simulated time of the step it shows. Pure functions of messages: :mod:`avp_viz.scene_node`
publishes them.

Several egos (``avp launch --egos K``): one scene node per ego, in ``/avp/ego<i>``, with frames prefixed ``ego<i>/``
(``map -> ego<i>/odom -> ego<i>/base_link``, ``map -> ego<i>/agent_<id>``) on the one global ``/tf``, so that one
viewer shows the whole lot in the frame ``map`` (namespaced ``/tf`` topics would need one viewer per ego); the ego, its
plan and its chosen spot are drawn in the ego's colour (:data:`EGO_COLOURS`).
"""

from __future__ import annotations

import math

import numpy as np
from geometry_msgs.msg import Point, TransformStamped
from std_msgs.msg import ColorRGBA
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import Marker, MarkerArray

from avp_common.markers import box_marker, marker, quat_z
from avp_viz.palette import EGO_RGB

MAP, ODOM, BASE = "map", "odom", "base_link"
#: marker namespaces, one per layer (a viewer can toggle each)
LAYERS = ("lot", "spots", "vehicles", "pedestrians", "predictions", "plan", "chosen_spot", "ego")
UNSEEN = (0.55, 0.55, 0.55, 0.35)
#: ego i's colour among several egos (ego, plan, chosen spot); one ego keeps the red ego and green/blue plan
EGO_COLOURS = tuple((*rgb, 1.0) for rgb in EGO_RGB)  # RGBA (avp_viz.palette)


def agent_frame(agent_id: int) -> str:
    return f"agent_{int(agent_id)}"


def _transform(parent: str, child: str, pose, stamp) -> TransformStamped:
    t = TransformStamped()
    t.header.stamp, t.header.frame_id, t.child_frame_id = stamp, parent, child
    t.transform.translation.x, t.transform.translation.y = float(pose[0]), float(pose[1])
    t.transform.rotation.z, t.transform.rotation.w = quat_z(float(pose[2]))
    return t


def static_transforms(stamp, prefix: str = "") -> TFMessage:
    """``map -> odom``: identity (perfect localisation in the simulator). ``prefix``: ``ego<i>/`` among K egos."""
    return TFMessage(transforms=[_transform(MAP, prefix + ODOM, (0.0, 0.0, 0.0), stamp)])


def transforms(obs, stamp, prefix: str = "") -> TFMessage:
    """``odom -> base_link`` (the ego) and ``map -> agent_<id>`` for each observed vehicle of observation ``obs``
    (child frames prefixed with ``prefix``)."""
    tfs = [_transform(prefix + ODOM, prefix + BASE, obs.ego_pose, stamp)]
    tfs += [_transform(MAP, prefix + agent_frame(v.id), v.pose, stamp) for v in obs.vehicles]
    return TFMessage(transforms=tfs)


def belief_color(b: float) -> tuple[float, float, float, float]:
    """Green (vacant, b = 0) to red (occupied, b = 1); NaN (never observed) grey."""
    if not np.isfinite(b):
        return UNSEEN
    b = float(min(max(b, 0.0), 1.0))
    return (0.15 + 0.75 * b, 0.8 - 0.6 * b, 0.2, 0.55)


def _pts(xy, z: float = 0.0) -> list[Point]:
    return [Point(x=float(x), y=float(y), z=z) for x, y in xy]


def _corners(x: float, y: float, theta: float, length: float, width: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    local = np.array([[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5]]) * (length, width)
    return local @ np.array([[c, s], [-s, c]]) + (x, y)


def lot_markers(lot, stamp) -> MarkerArray:
    """``viz/lot`` (latched, once per lot): the lot's boundary and every spot's outline."""
    boundary = marker("lot", 0, Marker.LINE_STRIP, stamp, (0.85, 0.85, 0.85, 1.0), width=0.15)
    boundary.points = _pts(np.vstack([lot.boundary, lot.boundary[:1]]))
    outlines = marker("lot", 1, Marker.LINE_LIST, stamp, (0.95, 0.95, 0.95, 0.8), width=0.05)
    for s in lot.spots:
        c = _corners(s.x, s.y, s.heading, s.length, s.width)
        outlines.points += _pts(np.repeat(np.vstack([c, c[:1]]), 2, axis=0)[1:-1], 0.01)
    return MarkerArray(markers=[boundary, outlines])


BELIEF_LEVELS = 20  # the spot fill's colours are the belief rounded to 1/20 (what a viewer can tell apart)


def belief_levels(beliefs: np.ndarray | None, n: int) -> np.ndarray:
    """Per spot: its colour level, round(20 b) in 0..20, or -1 for never observed (NaN) or no beliefs yet."""
    if beliefs is None:
        return np.full(n, -1, dtype=np.int64)
    b = np.asarray(beliefs, dtype=float)
    return np.where(np.isfinite(b), np.rint(np.clip(np.nan_to_num(b), 0.0, 1.0) * BELIEF_LEVELS), -1).astype(np.int64)


class SpotFill:
    """``viz/spots``: all spots of a lot as one triangle list coloured by belief level (:func:`belief_levels`).
    The geometry and the colours are built once; a node publishes a new fill only when a level changed."""

    def __init__(self, lot) -> None:
        self.points = []
        for s in lot.spots:
            c = _corners(s.x, s.y, s.heading, s.length, s.width)
            self.points += _pts(c[[0, 1, 2, 0, 2, 3]], 0.02)
        self.palette = {lvl: ColorRGBA(**dict(zip("rgba", map(float, belief_color(
            lvl / BELIEF_LEVELS if lvl >= 0 else np.nan)), strict=True))) for lvl in range(-1, BELIEF_LEVELS + 1)}

    def marker(self, levels: np.ndarray, stamp) -> MarkerArray:
        m = marker("spots", 0, Marker.TRIANGLE_LIST, stamp, (1.0, 1.0, 1.0, 1.0))
        m.points = self.points
        m.colors = [self.palette[int(lvl)] for lvl in levels for _ in range(6)]
        return MarkerArray(markers=[m])


def scene_markers(lot, obs, predictions, decision, stamp, trace=None, ego_rgba=None) -> MarkerArray:
    """``viz/scene``, one step's moving part (see the module docstring): observed vehicles and pedestrians,
    predictions, the ego, its plan and chosen spot. ``obs``: the core Observation; ``predictions``:
    PredictedTrajectoryArray message or None; ``decision``: PlannerDecision or None; ``trace``: the planner's
    DecisionTrace or None — while the ego waits for an agent, that agent is ringed in red and the cause is written
    above the ego. ``ego_rgba``: among several egos, this ego's colour for it, its plan and chosen spot."""
    arr = MarkerArray()
    clear = Marker()
    clear.action = Marker.DELETEALL
    arr.markers.append(clear)
    for v in obs.vehicles:
        rgba = (0.3, 0.4, 0.95, 0.9) if v.is_static else (0.95, 0.85, 0.1, 0.95)
        arr.markers.append(box_marker("vehicles", v.id, v.pose, v.length, v.width, 1.5, rgba, stamp))
    for p in obs.pedestrians:
        m = marker("pedestrians", p.id, Marker.CYLINDER, stamp, (0.95, 0.95, 0.95, 0.95))
        m.pose.position.x, m.pose.position.y, m.pose.position.z = float(p.position[0]), float(p.position[1]), 0.9
        m.scale.x = m.scale.y = 2 * float(p.radius)
        m.scale.z = 1.8
        arr.markers.append(m)
    for i, t in enumerate(predictions.trajectories if predictions is not None else ()):
        if len(t.poses) < 2:
            continue
        alpha = 0.25 + 0.75 * float(min(max(t.probability, 0.0), 1.0))
        m = marker("predictions", i, Marker.LINE_STRIP, stamp, (1.0, 0.2, 0.85, alpha), width=0.15)
        m.points = _pts([(q.x, q.y) for q in t.poses], 0.3)
        arr.markers.append(m)
    arr.markers.append(box_marker("ego", 0, obs.ego_pose, obs.ego_length, obs.ego_width, 1.5,
                                  ego_rgba or EGO_COLOURS[0], stamp))
    if decision is not None:
        arr.markers += _plan_markers(lot, decision, stamp, ego_rgba)
    if trace is not None and trace.cause:
        arr.markers += _blocking_markers(obs, trace, stamp)
    return arr


def _blocking_markers(obs, trace, stamp) -> list[Marker]:
    """The blocking agent ringed (red circle) and the cause as text over the ego."""
    out = []
    agents = obs.pedestrians if trace.agent_is_pedestrian else obs.vehicles
    at = next(((float(a.position[0]), float(a.position[1])) if trace.agent_is_pedestrian
               else (float(a.pose[0]), float(a.pose[1])) for a in agents if int(a.id) == int(trace.agent_id)), None)
    if at is not None:
        r = 1.2 if trace.agent_is_pedestrian else 3.2
        ang = np.linspace(0.0, 2 * np.pi, 33)
        m = marker("blocking_agent", 0, Marker.LINE_STRIP, stamp, (1.0, 0.1, 0.1, 1.0), width=0.25)
        m.points = _pts(np.column_stack([at[0] + r * np.cos(ang), at[1] + r * np.sin(ang)]), 0.4)
        out.append(m)
    text = trace.cause_key + (f" {int(trace.agent_id)} (p {trace.probability:.2f}, conflict in "
                              f"{0.1 * trace.conflict_step:.1f} s)" if trace.agent_id >= 0 else "")
    t = marker("why", 0, Marker.TEXT_VIEW_FACING, stamp, (1.0, 1.0, 1.0, 1.0))
    t.pose.position.x, t.pose.position.y, t.pose.position.z = float(obs.ego_pose[0]), float(obs.ego_pose[1]), 3.0
    t.scale.z = 1.0
    t.text = f"waiting {0.1 * trace.idle_steps:.1f} s: {text}"
    out.append(t)
    return out


def _plan_markers(lot, decision, stamp, ego_rgba=None) -> list[Marker]:
    out = []
    parking = decision.mode == decision.MODE_PARK
    if len(decision.plan.poses) >= 2:
        rgba = ego_rgba or ((0.1, 0.85, 0.3, 1.0) if parking else (0.2, 0.5, 1.0, 1.0))
        m = marker("plan", 0, Marker.LINE_STRIP, stamp, rgba, width=0.25)
        m.points = _pts([(p.pose.position.x, p.pose.position.y) for p in decision.plan.poses], 0.2)
        out.append(m)
    idx = {s.id: s for s in lot.spots}
    if parking and int(decision.spot_id) in idx:
        s = idx[int(decision.spot_id)]
        c = _corners(s.x, s.y, s.heading, s.length, s.width)
        m = marker("chosen_spot", 0, Marker.LINE_STRIP, stamp, ego_rgba or (0.1, 1.0, 0.3, 1.0), width=0.3)
        m.points = _pts(np.vstack([c, c[:1]]), 0.05)
        out.append(m)
    return out

"""Marker helpers the graph's viewers share (the simulator's ground-truth ``debug/markers``, the scene node's
``viz/*``): a coloured marker in frame ``map`` and a box footprint (visualization_msgs, REP-105 frames)."""

from __future__ import annotations

import math

from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker

MAP = "map"


def quat_z(theta: float) -> tuple[float, float]:
    """(z, w) of the unit quaternion of a rotation by ``theta`` about z (x = y = 0)."""
    return math.sin(theta / 2.0), math.cos(theta / 2.0)


def marker(ns: str, mid: int, kind: int, stamp, rgba, width: float = 0.0, frame: str = MAP) -> Marker:
    """A marker of type ``kind`` (unit scale, identity orientation); ``width``: the line width of strips/lists."""
    m = Marker()
    m.header.frame_id, m.header.stamp = frame, stamp
    m.ns, m.id, m.type, m.action = ns, int(mid), kind, Marker.ADD
    m.pose.orientation.w = 1.0
    m.scale.x = m.scale.y = m.scale.z = 1.0
    if width:
        m.scale.x = float(width)
    m.color = ColorRGBA(r=float(rgba[0]), g=float(rgba[1]), b=float(rgba[2]), a=float(rgba[3]))
    return m


def box_marker(ns: str, mid: int, pose, length: float, width: float, height: float, rgba, stamp) -> Marker:
    """A CUBE of ``length`` x ``width`` x ``height`` standing on the ground at ``pose`` = (x, y, theta)."""
    m = marker(ns, mid, Marker.CUBE, stamp, rgba)
    m.pose.position.x, m.pose.position.y, m.pose.position.z = float(pose[0]), float(pose[1]), height / 2
    m.pose.orientation.z, m.pose.orientation.w = quat_z(float(pose[2]))
    m.scale.x, m.scale.y, m.scale.z = float(length), float(width), float(height)
    return m

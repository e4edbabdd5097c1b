"""Markers of noisy sensing for viewers (docs/perception.md, docs/foxglove.md): the raw detections of a step
(autoware_perception_msgs/DetectedObjects: orange outlines, clutter included, no ids) and the tracker's tracks
(TrackedObjects: translucent cyan boxes with their ids), apart, so that a viewer sees what the tracker made of what it
was given."""

from __future__ import annotations

import math

from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

DETECTION = ColorRGBA(r=1.0, g=0.55, b=0.0, a=1.0)
TRACK = ColorRGBA(r=0.0, g=0.8, b=0.9, a=0.45)
TRACK_TEXT = ColorRGBA(r=0.0, g=0.55, b=0.65, a=1.0)


def _yaw(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _outline(pose, length: float, width: float, is_disc: bool) -> list[Point]:
    x, y, th = pose.position.x, pose.position.y, _yaw(pose.orientation)
    if is_disc:
        r = 0.5 * length
        return [Point(x=x + r * math.cos(a), y=y + r * math.sin(a), z=0.1)
                for a in (2 * math.pi * i / 12 for i in range(13))]
    c, s = math.cos(th), math.sin(th)
    pts = [(0.5 * length, 0.5 * width), (-0.5 * length, 0.5 * width), (-0.5 * length, -0.5 * width),
           (0.5 * length, -0.5 * width), (0.5 * length, 0.5 * width), (0.7 * length, 0.0), (0.5 * length, -0.5 * width)]
    return [Point(x=x + c * u - s * v, y=y + s * u + c * v, z=0.1) for u, v in pts]  # the nose marks the heading


def detection_markers(msg, frame: str = "map") -> MarkerArray:
    """One LINE_STRIP outline per detected object (namespace ``detections``), the step's old ones deleted first."""
    out = MarkerArray(markers=[Marker(action=Marker.DELETEALL, ns="detections")])
    out.markers[0].header.frame_id = frame
    for i, o in enumerate(msg.objects):
        m = Marker(ns="detections", id=i, type=Marker.LINE_STRIP, action=Marker.ADD, color=DETECTION)
        m.header.stamp, m.header.frame_id = msg.header.stamp, frame
        m.scale.x = 0.08
        m.pose.orientation.w = 1.0
        d = o.shape.dimensions
        m.points = _outline(o.kinematics.pose_with_covariance.pose, d.x, d.y, o.shape.type == 1)
        out.markers.append(m)
    return out


def track_markers(msg, frame: str = "map") -> MarkerArray:
    """One translucent CUBE (vehicle) or CYLINDER (pedestrian) per track and its id as text (namespace ``tracks``)."""
    out = MarkerArray(markers=[Marker(action=Marker.DELETEALL, ns="tracks")])
    out.markers[0].header.frame_id = frame
    for i, o in enumerate(msg.objects):
        pose = o.kinematics.pose_with_covariance.pose
        d = o.shape.dimensions
        m = Marker(ns="tracks", id=2 * i, type=Marker.CYLINDER if o.shape.type == 1 else Marker.CUBE,
                   action=Marker.ADD, color=TRACK)
        m.header.stamp, m.header.frame_id = msg.header.stamp, frame
        m.pose = pose
        m.pose.position.z = 0.75
        m.scale.x, m.scale.y, m.scale.z = max(d.x, 0.1), max(d.y, 0.1), 1.5
        t = Marker(ns="tracks", id=2 * i + 1, type=Marker.TEXT_VIEW_FACING, action=Marker.ADD, color=TRACK_TEXT)
        t.header = m.header
        t.pose.position.x, t.pose.position.y, t.pose.position.z = pose.position.x, pose.position.y, 2.0
        t.pose.orientation.w = 1.0
        t.scale.z = 0.8
        t.text = f"track {int.from_bytes(bytes(o.object_id.uuid[8:]), 'big')}"
        out.markers += [m, t]
    return out

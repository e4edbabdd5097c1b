"""Detections and tracks as Autoware's messages (autoware_perception_msgs/DetectedObjects, TrackedObjects), both
ways, checked on the way in (docs/perception.md, "A real detector"; docs/bad_input.md).

A vehicle is a BOUNDING_BOX of label CAR with its pose's covariance (x, y, yaw in the 6x6 row-major
PoseWithCovariance), ``orientation_availability`` AVAILABLE (or SIGN_UNKNOWN: the tracker then treats the heading as
an axis) and, where the detector gives one, a speed along its heading (``has_twist``); a pedestrian is a CYLINDER of
label PEDESTRIAN (dimensions.x = its diameter). Every other label is read as a vehicle when its shape is a box, and
dropped otherwise. Frames: every object is in the map frame (``header.frame_id`` "map", an episode tag allowed).
"""

from __future__ import annotations

import math

import numpy as np

from avp_world.detections import (
    LABEL_CAR,
    LABEL_PEDESTRIAN,
    ORIENTATION_AVAILABLE,
    ORIENTATION_SIGN_UNKNOWN,
    PedestrianDetection,
    VehicleDetection,
)

#: the most objects one DetectedObjects message may hold; more: the message is refused whole
MAX_OBJECTS = 1000
MAP_FRAME = "map"
#: a pose's covariance index (row-major 6x6: x, y, z, roll, pitch, yaw)
_XX, _XY, _YX, _YY, _TT = 0, 1, 6, 7, 35


class DetectionError(ValueError):
    """A detection message that cannot be read (its message names the field)."""


def _quat(theta: float):
    from geometry_msgs.msg import Quaternion

    return Quaternion(x=0.0, y=0.0, z=math.sin(0.5 * theta), w=math.cos(0.5 * theta))


def _yaw(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def detections_to_msg(vehicles, pedestrians, header):
    """DetectedObjects of core detections (avp_world.detections) under ``header``."""
    from autoware_perception_msgs.msg import DetectedObject, DetectedObjects, ObjectClassification, Shape

    msg = DetectedObjects(header=header)
    for d in vehicles:
        o = DetectedObject(existence_probability=float(d.existence))
        o.classification = [ObjectClassification(label=int(d.label), probability=1.0)]
        k = o.kinematics
        k.pose_with_covariance.pose.position.x = float(d.pose[0])
        k.pose_with_covariance.pose.position.y = float(d.pose[1])
        k.pose_with_covariance.pose.orientation = _quat(float(d.pose[2]))
        cov = np.zeros(36)
        c = np.asarray(d.covariance, float)
        cov[[_XX, _XY, _YX, _YY, _TT]] = c[0, 0], c[0, 1], c[1, 0], c[1, 1], c[2, 2]
        k.pose_with_covariance.covariance = cov
        k.has_position_covariance = True
        k.orientation_availability = int(d.orientation)
        if math.isfinite(d.speed):
            k.twist_with_covariance.twist.linear.x = float(d.speed)
            tcov = np.zeros(36)
            tcov[0] = float(d.speed_variance) if math.isfinite(d.speed_variance) else 0.0
            k.twist_with_covariance.covariance = tcov
            k.has_twist, k.has_twist_covariance = True, math.isfinite(d.speed_variance)
        o.shape.type = Shape.BOUNDING_BOX
        o.shape.dimensions.x, o.shape.dimensions.y, o.shape.dimensions.z = float(d.length), float(d.width), 1.5
        msg.objects.append(o)
    for p in pedestrians:
        o = DetectedObject(existence_probability=float(p.existence))
        o.classification = [ObjectClassification(label=LABEL_PEDESTRIAN, probability=1.0)]
        k = o.kinematics
        k.pose_with_covariance.pose.position.x = float(p.position[0])
        k.pose_with_covariance.pose.position.y = float(p.position[1])
        k.pose_with_covariance.pose.orientation.w = 1.0
        cov = np.zeros(36)
        c = np.asarray(p.covariance, float)
        cov[[_XX, _XY, _YX, _YY]] = c[0, 0], c[0, 1], c[1, 0], c[1, 1]
        k.pose_with_covariance.covariance = cov
        k.has_position_covariance = True
        k.orientation_availability = 0
        o.shape.type = Shape.CYLINDER
        o.shape.dimensions.x = o.shape.dimensions.y = 2.0 * float(p.radius)
        o.shape.dimensions.z = 1.7
        msg.objects.append(o)
    return msg


#: what a detection without a covariance is assumed to have (Autoware's defaults for a normal car and a pedestrian:
#: 0.4 m, 22 degrees; 0.4 m)
DEFAULT_VEHICLE_SIGMA = (0.4, math.radians(22.0))
DEFAULT_PEDESTRIAN_SIGMA = 0.4


def detections_from_msg(msg, max_objects: int = MAX_OBJECTS) -> tuple[list, list]:
    """(vehicle detections, pedestrian detections) of a DetectedObjects message; DetectionError naming the first
    object and field that is not finite, a size that is not positive, a wrong frame, or too many objects."""
    frame = msg.header.frame_id.partition("#")[0]
    if frame != MAP_FRAME:
        raise DetectionError(f"header.frame_id '{frame}': detections must be in the '{MAP_FRAME}' frame")
    if len(msg.objects) > max_objects:
        raise DetectionError(f"objects: {len(msg.objects)} objects, at most {max_objects}")
    vehicles, peds = [], []
    for i, o in enumerate(msg.objects):
        where = f"objects[{i}]"
        k = o.kinematics
        p, q = k.pose_with_covariance.pose.position, k.pose_with_covariance.pose.orientation
        cov = np.asarray(k.pose_with_covariance.covariance, float)
        dims = o.shape.dimensions
        for field, values in (("kinematics.pose_with_covariance.pose.position", (p.x, p.y)),
                              ("kinematics.pose_with_covariance.pose.orientation", (q.x, q.y, q.z, q.w)),
                              ("kinematics.pose_with_covariance.covariance", cov),
                              ("shape.dimensions", (dims.x, dims.y)), ("existence_probability",
                                                                       (o.existence_probability,))):
            bad = [v for v in values if not math.isfinite(v)]
            if bad:
                raise DetectionError(f"{where}: {field} holds {bad[0]}: must be finite")
        label = max(o.classification, key=lambda c: c.probability).label if o.classification else 0
        existence = float(np.clip(o.existence_probability, 0.0, 1.0))
        if o.shape.type == 1 or label == LABEL_PEDESTRIAN:  # CYLINDER
            if dims.x <= 0:
                raise DetectionError(f"{where}: shape.dimensions.x (diameter) must be > 0, got {dims.x}")
            c2 = _position_cov(cov, k.has_position_covariance, DEFAULT_PEDESTRIAN_SIGMA)
            peds.append(PedestrianDetection(position=np.array([p.x, p.y]), radius=0.5 * float(dims.x),
                                            covariance=c2, existence=existence))
            continue
        if o.shape.type != 0:
            continue  # a polygon of something else: not a vehicle the tracker follows
        if dims.x <= 0 or dims.y <= 0:
            raise DetectionError(f"{where}: shape.dimensions (length {dims.x}, width {dims.y}) must be > 0")
        s_pos, s_yaw = DEFAULT_VEHICLE_SIGMA
        c3 = np.zeros((3, 3))
        c3[:2, :2] = _position_cov(cov, k.has_position_covariance, s_pos)
        c3[2, 2] = cov[_TT] if k.has_position_covariance and cov[_TT] > 0 else s_yaw ** 2
        twist = k.twist_with_covariance
        speed = float(twist.twist.linear.x) if k.has_twist and math.isfinite(twist.twist.linear.x) else math.nan
        var = float(twist.covariance[0]) if k.has_twist_covariance and twist.covariance[0] > 0 else 1.0
        orient = k.orientation_availability if k.orientation_availability in (ORIENTATION_SIGN_UNKNOWN,
                                                                               ORIENTATION_AVAILABLE) else 0
        vehicles.append(VehicleDetection(pose=np.array([p.x, p.y, _yaw(q)]), length=float(dims.x),
                                         width=float(dims.y), covariance=c3, existence=existence,
                                         label=int(label) or LABEL_CAR, orientation=int(orient), speed=speed,
                                         speed_variance=var))
    return vehicles, peds


def _position_cov(cov: np.ndarray, has: bool, sigma: float) -> np.ndarray:
    c = np.array([[cov[_XX], cov[_XY]], [cov[_YX], cov[_YY]]])
    if not has or c[0, 0] <= 0 or c[1, 1] <= 0 or np.linalg.det(c) <= 0:
        return np.eye(2) * sigma * sigma
    return c


def track_uuid(track_id: int, episode: int) -> bytes:
    """16 bytes naming track ``track_id`` of ``episode``: the same track, the same UUID (Autoware draws them at
    random; ours stay reproducible, so that two runs of one seed record equal bags)."""
    return int(episode & (2**64 - 1)).to_bytes(8, "big") + int(track_id & (2**64 - 1)).to_bytes(8, "big")


def tracks_to_msg(tracks, header, episode: int = 0):
    """TrackedObjects of the tracker's tracks (avp_tracking.core.tracks.Track) under ``header``."""
    from autoware_perception_msgs.msg import ObjectClassification, Shape, TrackedObject, TrackedObjects

    msg = TrackedObjects(header=header)
    for t in tracks:
        o = TrackedObject(existence_probability=float(np.clip(t.existence, 0.0, 1.0)))
        o.object_id.uuid = list(track_uuid(t.id, episode))
        o.classification = [ObjectClassification(label=LABEL_PEDESTRIAN if t.pedestrian else LABEL_CAR,
                                                 probability=1.0)]
        k = o.kinematics
        pose = t.pose
        k.pose_with_covariance.pose.position.x, k.pose_with_covariance.pose.position.y = float(pose[0]), float(pose[1])
        k.pose_with_covariance.pose.orientation = _quat(float(pose[2]))
        cov = np.zeros(36)
        P = t.P
        cov[[_XX, _XY, _YX, _YY]] = P[0, 0], P[0, 1], P[1, 0], P[1, 1]
        cov[_TT] = P[2, 2] if not t.pedestrian else math.pi ** 2
        k.pose_with_covariance.covariance = cov
        k.twist_with_covariance.twist.linear.x = float(t.speed)
        if not t.pedestrian:
            k.twist_with_covariance.twist.angular.z = float(t.x[4])
        k.orientation_availability = 0 if t.pedestrian else ORIENTATION_AVAILABLE
        k.is_stationary = abs(t.speed) < 0.1
        if t.pedestrian:
            o.shape.type = Shape.CYLINDER
            o.shape.dimensions.x = o.shape.dimensions.y = 2.0 * float(t.radius)
            o.shape.dimensions.z = 1.7
        else:
            o.shape.type = Shape.BOUNDING_BOX
            o.shape.dimensions.x, o.shape.dimensions.y, o.shape.dimensions.z = *t.dims, 1.5
        msg.objects.append(o)
    return msg


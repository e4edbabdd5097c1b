"""Conversions between avp_msgs messages and the ROS-free core types (exact: float64 throughout).

Incoming messages are validated: a NaN/inf or an inconsistent array raises :class:`MessageError`
with a one-line reason, which nodes log (naming the topic) before dropping the message.
"""

from __future__ import annotations

import math

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose2D

from avp_msgs.msg import LotMap as LotMapMsg
from avp_msgs.msg import Observation as ObservationMsg
from avp_msgs.msg import ObservedPedestrian as ObservedPedestrianMsg
from avp_msgs.msg import ObservedVehicle as ObservedVehicleMsg
from avp_msgs.msg import Road as RoadMsg
from avp_msgs.msg import Spot as SpotMsg
from avp_world.lot import LotMap, lot_from_dict
from avp_world.types import Beacon, Observation, ObservedPedestrian, ObservedVehicle


class MessageError(ValueError):
    """An incoming message is malformed (NaN, inf, inconsistent sizes, unknown ids)."""


def step_to_time(step: int, dt: float) -> Time:
    """Sim time t = step * dt as builtin_interfaces/Time (integer nanoseconds, no float drift)."""
    ns = step_to_ns(step, dt)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def step_to_ns(step: int, dt: float) -> int:
    return int(step) * int(round(dt * 1e9))


def time_to_ns(t: Time) -> int:
    return int(t.sec) * 1_000_000_000 + int(t.nanosec)


def _finite(values, what: str) -> None:
    arr = np.asarray(values, dtype=float)
    if arr.size and not np.all(np.isfinite(arr)):
        raise MessageError(f"{what}: contains NaN or inf")


# ---------------------------------------------------------------------------------------------- lot


def lot_to_msg(lot: LotMap) -> LotMapMsg:
    msg = LotMapMsg()
    msg.header.frame_id = "map"
    msg.name = lot.name
    msg.boundary = [Point(x=float(x), y=float(y), z=0.0) for x, y in lot.boundary]
    msg.entrance = Point(x=float(lot.entrance[0]), y=float(lot.entrance[1]), z=0.0)
    msg.spots = [
        SpotMsg(id=s.id, pose=Pose2D(x=s.x, y=s.y, theta=s.heading), length=s.length, width=s.width)
        for s in lot.spots
    ]
    msg.roads = [
        RoadMsg(id=r.id, start=Point(x=r.start[0], y=r.start[1], z=0.0), end=Point(x=r.end[0], y=r.end[1], z=0.0),
                width=r.width)
        for r in lot.roads
    ]
    return msg


def lot_from_msg(msg: LotMapMsg, source: str = "lot_map topic") -> LotMap:
    """Rebuild (and validate) the lot from its message; raises LotMapError on a bad map."""
    data = {
        "name": msg.name,
        "boundary": [[p.x, p.y] for p in msg.boundary],
        "entrance": [msg.entrance.x, msg.entrance.y],
        "roads": [{"id": r.id, "start": [r.start.x, r.start.y], "end": [r.end.x, r.end.y], "width": r.width}
                  for r in msg.roads],
        "spots": [{"id": s.id, "center": [s.pose.x, s.pose.y], "heading": s.pose.theta, "length": s.length,
                   "width": s.width} for s in msg.spots],
    }
    return lot_from_dict(data, source=source)


# ---------------------------------------------------------------------------------------- observation


def lot_from_msg_or_log(msg: LotMapMsg, logger) -> LotMap | None:
    """:func:`lot_from_msg` for a node's ``lot_map`` callback: None after one error line naming the topic (the
    node keeps its previous lot and keeps running)."""
    try:
        return lot_from_msg(msg)
    except ValueError as exc:
        logger.error(f"lot_map: {exc}")
        return None


def observation_to_msg(obs: Observation, frame_id: str = "map") -> ObservationMsg:
    msg = ObservationMsg()
    msg.header.frame_id = frame_id
    msg.header.stamp = step_to_time(obs.step, obs.dt)
    msg.step = int(obs.step)
    msg.dt = float(obs.dt)
    msg.ego_pose = Pose2D(x=float(obs.ego_pose[0]), y=float(obs.ego_pose[1]), theta=float(obs.ego_pose[2]))
    if obs.ego_covariance is not None:
        msg.ego_pose_covariance = [float(v) for v in np.asarray(obs.ego_covariance, float).reshape(9)]
    msg.ego_length = float(obs.ego_length)
    msg.ego_width = float(obs.ego_width)
    msg.ego_speed = float(obs.ego_speed)
    msg.vacant_spot_ids = [int(i) for i in obs.vacant_spot_ids]
    msg.occupied_spot_ids = [int(i) for i in obs.occupied_spot_ids]
    msg.vehicles = [
        ObservedVehicleMsg(
            id=int(v.id), length=float(v.length), width=float(v.width), is_static=bool(v.is_static),
            history=[Pose2D(x=float(p[0]), y=float(p[1]), theta=float(p[2])) for p in v.history],
        )
        for v in obs.vehicles
    ]
    msg.pedestrians = [
        ObservedPedestrianMsg(
            id=int(p.id), radius=float(p.radius),
            position=Point(x=float(p.position[0]), y=float(p.position[1]), z=0.0),
            previous_position=Point(x=float(p.previous_position[0]), y=float(p.previous_position[1]), z=0.0),
        )
        for p in obs.pedestrians
    ]
    msg.ray_angle_min = float(obs.ray_angle_min)
    msg.ray_angle_increment = float(obs.ray_angle_increment)
    msg.ray_ranges = np.asarray(obs.ray_ranges, dtype=np.float32)
    return msg


#: a fleet's beacons (avp_planner.core.ego_yield): at most this many in one EgoBeaconArray (K <= 8 egos) ...
MAX_BEACONS = 7
#: ... and at most this many poses of path in one (avp_planner.core.ego_yield.MAX_BEACON_POSES)
MAX_BEACON_POSES = 200


def poses_to_msg(poses) -> list:
    """(N, 3) poses as geometry_msgs/Pose2D (float64: exact)."""
    return [Pose2D(x=float(p[0]), y=float(p[1]), theta=float(p[2])) for p in np.asarray(poses, float).reshape(-1, 3)]


def beacon_to_msg(b: Beacon):
    from avp_msgs.msg import EgoBeacon

    return EgoBeacon(ego=int(b.ego), pose=poses_to_msg([b.pose])[0], waiting=bool(b.waiting), path=poses_to_msg(b.path))


def beacon_from_msg(m) -> Beacon:
    """Core beacon from its message; raises MessageError for NaN/inf or a path over MAX_BEACON_POSES poses."""
    if len(m.path) > MAX_BEACON_POSES:
        raise MessageError(f"beacon of ego {m.ego}: {len(m.path)} path poses, at most {MAX_BEACON_POSES}")
    pose = np.array([m.pose.x, m.pose.y, m.pose.theta])
    path = np.array([[q.x, q.y, q.theta] for q in m.path], dtype=float).reshape(-1, 3)
    _finite(pose, f"beacon of ego {m.ego}: pose")
    _finite(path, f"beacon of ego {m.ego}: path")
    return Beacon(int(m.ego), pose, bool(m.waiting), path)


def observation_from_msg(msg: ObservationMsg) -> Observation:
    """Core observation from its message; raises MessageError for NaN/inf or inconsistent fields."""
    if not (math.isfinite(msg.dt) and msg.dt > 0):
        raise MessageError(f"dt must be > 0 and finite, got {msg.dt}")
    pose = np.array([msg.ego_pose.x, msg.ego_pose.y, msg.ego_pose.theta])
    _finite(pose, "ego_pose")
    _finite([msg.ego_length, msg.ego_width, msg.ego_speed], "ego size/speed")
    cov = np.asarray(msg.ego_pose_covariance, dtype=float).reshape(3, 3)
    _finite(cov, "ego_pose_covariance")
    vehicles = []
    for v in msg.vehicles:
        hist = np.array([[p.x, p.y, p.theta] for p in v.history]).reshape(-1, 3)
        if len(hist) == 0:
            raise MessageError(f"vehicle {v.id}: empty history")
        _finite(hist, f"vehicle {v.id} history")
        _finite([v.length, v.width], f"vehicle {v.id} size")
        vehicles.append(ObservedVehicle(int(v.id), float(v.length), float(v.width), bool(v.is_static), hist))
    peds = []
    for p in msg.pedestrians:
        pos = np.array([p.position.x, p.position.y])
        prev = np.array([p.previous_position.x, p.previous_position.y])
        _finite(np.concatenate([pos, prev, [p.radius]]), f"pedestrian {p.id}")
        peds.append(ObservedPedestrian(int(p.id), float(p.radius), pos, prev))
    ranges = np.asarray(msg.ray_ranges, dtype=np.float32)
    _finite(ranges, "ray_ranges")
    return Observation(
        step=int(msg.step),
        dt=float(msg.dt),
        ego_pose=pose,
        ego_length=float(msg.ego_length),
        ego_width=float(msg.ego_width),
        ego_speed=float(msg.ego_speed),
        vacant_spot_ids=np.asarray(msg.vacant_spot_ids, dtype=np.int64),
        occupied_spot_ids=np.asarray(msg.occupied_spot_ids, dtype=np.int64),
        vehicles=tuple(vehicles),
        pedestrians=tuple(peds),
        ray_angle_min=float(msg.ray_angle_min),
        ray_angle_increment=float(msg.ray_angle_increment),
        ray_ranges=ranges,
        ego_covariance=cov if cov.any() else None,
    )


def beacons_to_msg(step: int, dt: float, beacons) -> object:
    """avp_msgs/EgoBeaconArray of what one ego hears for ``step``."""
    from avp_msgs.msg import EgoBeaconArray

    msg = EgoBeaconArray()
    msg.header.frame_id = "map"
    msg.header.stamp = step_to_time(step, dt)
    msg.step = int(step)
    msg.beacons = [beacon_to_msg(b) for b in beacons]
    return msg


def beacons_from_msg(msg) -> tuple[Beacon, ...]:
    """The beacons of an avp_msgs/EgoBeaconArray; raises MessageError for more than MAX_BEACONS, a path over
    MAX_BEACON_POSES poses, or NaN/inf."""
    if len(msg.beacons) > MAX_BEACONS:
        raise MessageError(f"{len(msg.beacons)} beacons, at most {MAX_BEACONS}")
    return tuple(beacon_from_msg(b) for b in msg.beacons)


# ------------------------------------------------------------------------------- beliefs / predictions


def beliefs_to_msg(step: int, dt: float, spot_ids: np.ndarray, beliefs: np.ndarray):
    from avp_msgs.msg import SpotBeliefs

    msg = SpotBeliefs()
    msg.header.frame_id = "map"
    msg.header.stamp = step_to_time(step, dt)
    msg.step = int(step)
    msg.spot_ids = [int(i) for i in spot_ids]
    msg.beliefs = np.asarray(beliefs, dtype=np.float32)
    return msg


def beliefs_from_msg(msg, lot: LotMap) -> np.ndarray:
    """Belief vector indexed like ``lot.spots``; MessageError on unknown ids, NaN or values outside [0, 1]."""
    if len(msg.spot_ids) != len(msg.beliefs):
        raise MessageError(f"{len(msg.spot_ids)} spot ids but {len(msg.beliefs)} beliefs")
    b = np.full(lot.n_spots, 0.5)
    vals = np.asarray(msg.beliefs, dtype=float)
    _finite(vals, "beliefs")
    if vals.size and (vals.min() < 0 or vals.max() > 1):
        raise MessageError("beliefs must lie in [0, 1]")
    for sid, v in zip(msg.spot_ids, vals, strict=True):
        if not lot.has_spot(sid):
            raise MessageError(f"unknown spot id {sid}")
        b[lot.spot_index(sid)] = v
    return b


def predictions_to_msg(step: int, dt: float, predictions):
    from avp_msgs.msg import PredictedTrajectory as PredMsg
    from avp_msgs.msg import PredictedTrajectoryArray

    msg = PredictedTrajectoryArray()
    msg.header.frame_id = "map"
    msg.header.stamp = step_to_time(step, dt)
    msg.step = int(step)
    for p in predictions:
        goal = getattr(p, "goal", None)
        kind = (PredMsg.INTENT_SPOT if p.spot_id >= 0 else PredMsg.INTENT_EXPLORE if goal is not None
                else PredMsg.INTENT_NONE)
        m = PredMsg(agent_id=int(p.agent_id), agent_type=PredMsg.AGENT_PEDESTRIAN if p.is_pedestrian
                    else PredMsg.AGENT_VEHICLE, length=float(p.length), width=float(p.width), radius=float(p.radius),
                    intention_kind=kind, spot_id=int(p.spot_id), probability=float(p.probability), dt=float(p.dt))
        m.poses = [Pose2D(x=float(q[0]), y=float(q[1]), theta=float(q[2])) for q in p.poses]
        if goal is not None:  # the conditioning goal (spot pose or exploration point)
            m.goal = Pose2D(x=float(goal[0]), y=float(goal[1]), theta=float(goal[2]))
        elif len(p.poses):  # unconditioned: where the prediction ends
            m.goal = m.poses[-1]
        msg.trajectories.append(m)
    return msg


def predictions_from_msg(msg):
    from avp_msgs.msg import PredictedTrajectory as PredMsg
    from avp_world.types import PredictedTrajectory

    out = []
    for m in msg.trajectories:
        poses = np.array([[q.x, q.y, q.theta] for q in m.poses]).reshape(-1, 3)
        _finite(poses, f"prediction of agent {m.agent_id}")
        _finite([m.probability, m.dt, m.length, m.width, m.radius], f"prediction of agent {m.agent_id}")
        if not (m.dt > 0):
            raise MessageError(f"prediction of agent {m.agent_id}: dt must be > 0")
        goal = None
        if m.intention_kind != PredMsg.INTENT_NONE:
            goal = np.array([m.goal.x, m.goal.y, m.goal.theta])
            _finite(goal, f"prediction of agent {m.agent_id} goal")
        out.append(PredictedTrajectory(agent_id=int(m.agent_id), poses=poses, dt=float(m.dt),
                                       probability=float(m.probability),
                                       is_pedestrian=m.agent_type == PredMsg.AGENT_PEDESTRIAN, length=float(m.length),
                                       width=float(m.width), radius=float(m.radius), spot_id=int(m.spot_id),
                                       goal=goal))
    return out


# ------------------------------------------------------------------------------------------ validation


def check_probabilities(values, what: str) -> np.ndarray:
    """float64 copy of float32 message probabilities; MessageError for NaN/inf or values outside [0, 1]."""
    p = np.asarray(values, dtype=np.float32).astype(float)
    _finite(p, what)
    if p.size and (p.min() < 0.0 or p.max() > 1.0):
        raise MessageError(f"{what}: probabilities must lie in [0, 1]")
    return p


def check_finite(values, what: str) -> None:
    """MessageError naming ``what`` if ``values`` contain NaN or inf."""
    _finite(values, what)


def check_stamp(header_stamp, step: int, dt: float) -> None:
    """MessageError unless the header stamp is exactly t = step * dt (integer nanoseconds)."""
    got, want = time_to_ns(header_stamp), step_to_ns(step, dt)
    if got != want:
        raise MessageError(f"header.stamp {got} ns does not match step {step} (expected {want} ns)")

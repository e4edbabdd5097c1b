"""MarkerArray of the world for RViz / Foxglove (frame 'map'): lot, spots, vehicles, ego, rays."""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from avp_common.markers import box_marker


def _color(r: float, g: float, b: float, a: float = 1.0) -> tuple[float, float, float, float]:
    return (r, g, b, a)


def world_markers(lot, world, obs, stamp) -> MarkerArray:
    arr = MarkerArray()
    clear = Marker()
    clear.action = Marker.DELETEALL
    arr.markers.append(clear)
    occupied, _ = world.occupancy()
    for k, s in enumerate(lot.spots):
        c = _color(0.9, 0.3, 0.3, 0.35) if occupied[k] else _color(0.2, 0.8, 0.2, 0.35)
        arr.markers.append(box_marker("spots", s.id, (s.x, s.y, s.heading), s.length, s.width, 0.02, c, stamp))
    for i in range(len(world.states)):
        c = _color(0.3, 0.3, 0.9) if not world.is_dynamic[i] else _color(0.95, 0.85, 0.1)
        arr.markers.append(box_marker("vehicles", int(world.vehicle_ids[i]), world.states[i], world.vehicle_dims[i, 0],
                                world.vehicle_dims[i, 1], 1.5, c, stamp))
    arr.markers.append(box_marker("ego", 0, world.ego, world.scenario.ego.length, world.scenario.ego.width, 1.5,
                            _color(0.9, 0.1, 0.1), stamp))
    rays = Marker()
    rays.header.frame_id = "map"
    rays.header.stamp = stamp
    rays.ns, rays.id, rays.type, rays.action = "rays", 0, Marker.LINE_LIST, Marker.ADD
    rays.scale.x = 0.03
    rays.color = ColorRGBA(r=1.0, g=0.6, b=0.0, a=0.4)
    ends = obs.ray_endpoints()[::4]
    o = Point(x=float(world.ego[0]), y=float(world.ego[1]), z=0.1)
    pts = []
    for e in ends:
        pts += [o, Point(x=float(e[0]), y=float(e[1]), z=0.1)]
    rays.points = pts
    arr.markers.append(rays)
    boundary = Marker()
    boundary.header.frame_id = "map"
    boundary.header.stamp = stamp
    boundary.ns, boundary.id, boundary.type, boundary.action = "lot", 0, Marker.LINE_STRIP, Marker.ADD
    boundary.scale.x = 0.1
    boundary.color = ColorRGBA(r=0.8, g=0.8, b=0.8, a=1.0)
    b = np.vstack([lot.boundary, lot.boundary[:1]])
    boundary.points = [Point(x=float(x), y=float(y), z=0.0) for x, y in b]
    arr.markers.append(boundary)
    return arr

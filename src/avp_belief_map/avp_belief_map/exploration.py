"""Exploration points (§V-A, defined in §V-D), ROS-free: the crossings of the road centre lines with the boundary
of a circle (the sensing disc) or of the BEV crop square around a vehicle, as poses facing away from its centre,
and their ranking. The intent model (:mod:`avp_predictors.intent_model`) scores them beside the spots.
"""

from __future__ import annotations

import math

import numpy as np

from avp_world.geometry import wrap_angle
from avp_world.lot import LotMap


def _outward_poses(point: np.ndarray, direction: np.ndarray, heading: float, center: np.ndarray) -> list[np.ndarray]:
    """Pose(s) on a centre line with the road heading theta_R or theta_R + pi, whichever points away from
    ``center``; both where the road is perpendicular to the outward direction (it only touches the region)."""
    r = point - center
    out = float(direction[0] * r[0] + direction[1] * r[1])
    scale = math.hypot(direction[0], direction[1]) * math.hypot(r[0], r[1])
    if abs(out) <= 1e-9 * max(scale, 1.0):
        headings = [heading, heading + math.pi]
    else:
        headings = [heading if out > 0.0 else heading + math.pi]
    return [np.array([point[0], point[1], float(wrap_angle(th))]) for th in headings]


def exploration_points_circle(lot: LotMap, center: np.ndarray, radius: float) -> np.ndarray:
    """Intersections of the road centre lines C_j with the circle |p - center| = radius (§V-D definition).

    Returns (Q, 3) poses (x, y, theta) with theta in {theta_Rj, theta_Rj + pi} pointing away from ``center``
    (both where a centre line only touches the circle).
    """
    c = np.asarray(center, dtype=float)[:2]
    seg, heading = lot.road_segments, lot.road_headings
    p0 = seg[:, 0]
    d = seg[:, 1] - p0
    f = p0 - c
    a = np.einsum("ij,ij->i", d, d)
    b = 2.0 * np.einsum("ij,ij->i", f, d)
    disc = b * b - 4.0 * a * (np.einsum("ij,ij->i", f, f) - radius * radius)
    out: list[np.ndarray] = []
    for j in np.nonzero(disc >= 0.0)[0]:
        sq = math.sqrt(disc[j])
        for t in sorted({(-b[j] - sq) / (2.0 * a[j]), (-b[j] + sq) / (2.0 * a[j])}):
            if 0.0 <= t <= 1.0:
                out += _outward_poses(p0[j] + t * d[j], d[j], float(heading[j]), c)
    return _dedupe(out)


def exploration_points_square(lot: LotMap, pose: np.ndarray, half_extent: float) -> np.ndarray:
    """Crossings of the road centre lines with the boundary of the square of half side ``half_extent``
    centred on ``pose`` and rotated by its heading (the BEV crop; ParkPredict+'s "lanes", sheet §1.6).
    Segment ends inside the square are not crossings. Returns (Q, 3) poses pointing away from the centre."""
    c = np.asarray(pose[:2], dtype=float)
    cs, sn = math.cos(pose[2]), math.sin(pose[2])
    rot = np.array([[cs, -sn], [sn, cs]])
    seg, heading = lot.road_segments, lot.road_headings
    out: list[np.ndarray] = []
    for (p0, p1), th in zip(seg, heading, strict=True):
        q0, q1 = (p0 - c) @ rot, (p1 - c) @ rot  # local frame
        dq = q1 - q0
        t_in, t_out = -math.inf, math.inf
        for k in range(2):  # slab method on |x| <= h, |y| <= h
            if abs(dq[k]) < 1e-15:
                if abs(q0[k]) > half_extent:
                    t_in, t_out = 1.0, 0.0
                continue
            ta, tb = sorted(((-half_extent - q0[k]) / dq[k], (half_extent - q0[k]) / dq[k]))
            t_in, t_out = max(t_in, ta), min(t_out, tb)
        if t_in > t_out:
            continue
        d = p1 - p0
        for t in (t_in, t_out):
            if 0.0 < t < 1.0:
                out += _outward_poses(p0 + t * d, d, th, c)
    return _dedupe(out)


def _dedupe(points: list[np.ndarray], tol: float = 1e-6) -> np.ndarray:
    keep: list[np.ndarray] = []
    for p in points:
        if not any(np.all(np.abs(p[:2] - q[:2]) < tol) and abs(wrap_angle(p[2] - q[2])) < tol for q in keep):
            keep.append(p)
    return np.array(keep, dtype=float).reshape(-1, 3)


def rank_exploration_points(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Order points as ParkPredict+ ranks lanes: by -cos(heading, point - position), then by distance."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(pts) == 0:
        return pts
    d = pts[:, :2] - np.asarray(pose[:2], dtype=float)
    dist = np.hypot(d[:, 0], d[:, 1])
    cos = (d @ np.array([math.cos(pose[2]), math.sin(pose[2])])) / np.maximum(dist, 1e-12)
    order = np.lexsort((dist, -np.round(cos, 12)))
    return pts[order]

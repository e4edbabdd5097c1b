"""Vectorised planar geometry: oriented rectangles (vehicles, spots), angles, SAT overlap tests.

Conventions: a pose is ``(x, y, theta)``; a rectangle of length ``l`` (along the heading) and width
``w`` is centred on the pose (paper §II-B: V_k = {|x| <= l/2, |y| <= w/2} rotated and translated).
Corner order is counter-clockwise starting at the front-left corner.
"""

from __future__ import annotations

import numpy as np

_CORNER_SIGNS = np.array([[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5]])


def wrap_angle(a: np.ndarray | float) -> np.ndarray | float:
    """Wrap angles to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def rect_corners(poses: np.ndarray, length: np.ndarray | float, width: np.ndarray | float) -> np.ndarray:
    """Corners of oriented rectangles.

    Args:
        poses: (..., 3) array of (x, y, theta).
        length, width: scalars or arrays broadcastable to ``poses[..., 0]``.

    Returns:
        (..., 4, 2) corners, counter-clockwise from front-left.
    """
    poses = np.asarray(poses, dtype=float)
    x, y, th = poses[..., 0], poses[..., 1], poses[..., 2]
    length = np.broadcast_to(np.asarray(length, dtype=float), x.shape)
    width = np.broadcast_to(np.asarray(width, dtype=float), x.shape)
    c, s = np.cos(th), np.sin(th)
    lx = _CORNER_SIGNS[:, 0] * length[..., None]  # (..., 4)
    ly = _CORNER_SIGNS[:, 1] * width[..., None]
    cx = x[..., None] + c[..., None] * lx - s[..., None] * ly
    cy = y[..., None] + s[..., None] * lx + c[..., None] * ly
    return np.stack([cx, cy], axis=-1)


def _axes(corners: np.ndarray) -> np.ndarray:
    """The two edge normals of each rectangle: (..., 2, 2)."""
    e0 = corners[..., 0, :] - corners[..., 1, :]
    e1 = corners[..., 1, :] - corners[..., 2, :]
    axes = np.stack([e0, e1], axis=-2)
    return axes / np.linalg.norm(axes, axis=-1, keepdims=True)


def rects_overlap(a: np.ndarray, b: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """Separating-axis test for pairs of rectangles given as corners.

    Args:
        a, b: (..., 4, 2) corner arrays, broadcast against each other.
        margin: rectangles closer than ``margin`` along every axis count as overlapping
            (``margin=0`` means touching counts as overlap).

    Returns:
        Boolean array of the broadcast leading shape: True where the interiors (grown by margin) meet.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    a, b = np.broadcast_arrays(a, b)
    axes = np.concatenate([_axes(a), _axes(b)], axis=-2)  # (..., 4, 2)
    pa = np.einsum("...kd,...cd->...kc", axes, a)  # (..., 4 axes, 4 corners)
    pb = np.einsum("...kd,...cd->...kc", axes, b)
    separated = (pa.max(-1) + margin < pb.min(-1)) | (pb.max(-1) + margin < pa.min(-1))
    return ~separated.any(-1)


def points_in_rects(points: np.ndarray, corners: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Whether points lie inside (or on) rectangles.

    Args:
        points: (..., 2) points, broadcast against ``corners[..., 0, :]``.
        corners: (..., 4, 2) rectangle corners (as from :func:`rect_corners`).
    """
    p = np.asarray(points, dtype=float)
    c = np.asarray(corners, dtype=float)
    origin = c[..., 1, :]
    u = c[..., 0, :] - origin  # along length
    v = c[..., 2, :] - origin  # along width (towards the right side)
    d = p - origin
    du = np.einsum("...d,...d->...", d, u) / np.einsum("...d,...d->...", u, u)
    dv = np.einsum("...d,...d->...", d, v) / np.einsum("...d,...d->...", v, v)
    return (du >= -tol) & (du <= 1 + tol) & (dv >= -tol) & (dv <= 1 + tol)


def rect_inside_rect(inner: np.ndarray, outer: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Whether rectangle ``inner`` lies entirely inside ``outer`` (both convex: all corners inside).

    Args:
        inner: (..., 4, 2) corners; outer: (..., 4, 2) corners, broadcast.
    """
    inner = np.asarray(inner, dtype=float)
    outer = np.asarray(outer, dtype=float)
    return points_in_rects(inner, outer[..., None, :, :], tol=tol).all(-1)


def disc_rect_overlap(centers: np.ndarray, radii: np.ndarray | float, corners: np.ndarray) -> np.ndarray:
    """Whether discs overlap rectangles (closed sets). Shapes broadcast: centers (..., 2), corners (..., 4, 2)."""
    p = np.asarray(centers, dtype=float)
    c = np.asarray(corners, dtype=float)
    origin = c[..., 1, :]
    u = c[..., 0, :] - origin
    v = c[..., 2, :] - origin
    lu = np.linalg.norm(u, axis=-1)
    lv = np.linalg.norm(v, axis=-1)
    d = p - origin
    pu = np.einsum("...d,...d->...", d, u) / lu
    pv = np.einsum("...d,...d->...", d, v) / lv
    qu = np.clip(pu, 0.0, lu)
    qv = np.clip(pv, 0.0, lv)
    dist2 = (pu - qu) ** 2 + (pv - qv) ** 2
    return dist2 <= np.asarray(radii, dtype=float) ** 2


def polygon_contains_points(polygon: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon test (boundary points count as inside up to float noise).

    Args:
        polygon: (M, 2) vertices of a simple polygon (closed implicitly).
        points: (..., 2).
    """
    poly = np.asarray(polygon, dtype=float)
    p = np.asarray(points, dtype=float)
    x, y = p[..., 0][..., None], p[..., 1][..., None]
    x0, y0 = poly[:, 0], poly[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    crosses = (y0 > y) != (y1 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_at = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
    inside = (crosses & (x < x_at)).sum(-1) % 2 == 1
    # points on an edge are inside
    ex, ey = x1 - x0, y1 - y0
    t = np.clip(((x - x0) * ex + (y - y0) * ey) / np.maximum(ex * ex + ey * ey, 1e-300), 0.0, 1.0)
    on_edge = (np.hypot(x0 + t * ex - x, y0 + t * ey - y) < 1e-9).any(-1)
    return inside | on_edge


def segments_intersect(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """Whether closed segments p0-p1 and q0-q1 intersect (all args (..., 2), broadcast)."""

    def cross(a, b):
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]

    r = p1 - p0
    s = q1 - q0
    qp = q0 - p0
    denom = cross(r, s)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = cross(qp, s) / denom
        u = cross(qp, r) / denom
    proper = (np.abs(denom) > 1e-12) & (t >= 0) & (t <= 1) & (u >= 0) & (u <= 1)
    return proper

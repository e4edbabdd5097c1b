"""Ray geometry of the observation model (paper §III-A), vectorised with numpy: rays against polylines,
point-to-segment distances, the slab form of parallelograms (vehicles, spots) and ray-slab intervals.

Conventions are those of :mod:`avp_sensing.observation` (closed sets; "touching" counts).
"""

from __future__ import annotations

import numpy as np

SEG_PARAM_TOL = 1e-12  # slack on the segment parameter so rays through polygon vertices never slip through
CURVE_VERTICES = 256  # vertices of the drawing polygon of a disc / ellipse
TINY = 1e-300  # replaces exact zeros in n.d so that parallel rays give +-inf slab bounds, never NaN


def ray_polyline_t(
    directions: np.ndarray, seg_a: np.ndarray, seg_b: np.ndarray, t_min: float = 0.0
) -> np.ndarray:
    """First hit of rays from the origin with segments (origin-relative coordinates).

    Args:
        directions: (n, 2) unit ray directions.
        seg_a, seg_b: (M, 2) segment end points relative to the ray origin.
    Returns:
        (n,) smallest t >= t_min with ``t * d`` on some segment (inf where none).
    """
    if seg_a.shape[0] == 0:
        return np.full(directions.shape[0], np.inf)
    e = seg_b - seg_a  # (M, 2)
    dx, dy = directions[:, 0:1], directions[:, 1:2]  # (n, 1)
    denom = dx * e[:, 1] - dy * e[:, 0]  # d x e, (n, M)
    num_t = seg_a[:, 0] * e[:, 1] - seg_a[:, 1] * e[:, 0]  # w x e, (M,)
    num_s = seg_a[:, 0] * dy - seg_a[:, 1] * dx  # w x d, (n, M)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = num_t / denom
        s = num_s / denom
    ok = (denom != 0.0) & (t >= t_min) & (s >= -SEG_PARAM_TOL) & (s <= 1.0 + SEG_PARAM_TOL)
    return np.where(ok, t, np.inf).min(axis=1)


def point_segment_dist(seg_a: np.ndarray, seg_b: np.ndarray) -> np.ndarray:
    """(M,) distance from the origin to segments given relative to it."""
    e = seg_b - seg_a
    ee = np.maximum((e * e).sum(-1), 1e-300)
    s = np.clip(-(seg_a * e).sum(-1) / ee, 0.0, 1.0)
    q = seg_a + s[:, None] * e
    return np.sqrt((q * q).sum(-1))


def slabs(rel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Slab form of parallelograms given by corners relative to the ray origin.

    Args:
        rel: (K, 4, 2) corners (c0..c3 in order around the boundary).
    Returns:
        normals (2K, 2) (rows 2k, 2k+1 belong to parallelogram k; not normalised) and the signed
        offsets p1, p2 (slab 1: n1.x in [p1, p2] up to order) and q1, q2 (slab 2), each (K,).
    """
    u = rel[:, 0] - rel[:, 1]
    v = rel[:, 1] - rel[:, 2]
    n1 = np.stack([-u[:, 1], u[:, 0]], axis=-1)
    n2 = np.stack([-v[:, 1], v[:, 0]], axis=-1)
    c1, c2, c0 = rel[:, 1], rel[:, 2], rel[:, 0]
    p1 = (n1 * c1).sum(-1)
    p2 = (n1 * c2).sum(-1)
    q1 = (n2 * c1).sum(-1)
    q2 = (n2 * c0).sum(-1)
    normals = np.stack([n1, n2], axis=1).reshape(-1, 2)
    return normals, p1, p2, q1, q2


def slab_interval(
    normals: np.ndarray,
    p1: np.ndarray,
    p2: np.ndarray,
    q1: np.ndarray,
    q2: np.ndarray,
    directions: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Parameter interval [near, far] of each ray (from the origin) inside each parallelogram.

    Returns (K, n) arrays; the ray line meets parallelogram k iff near <= far.
    """
    k = p1.shape[0]
    nd = normals @ directions.T  # (2K, n)
    nd[nd == 0.0] = TINY
    inv = (1.0 / nd).reshape(k, 2, -1)
    inv1, inv2 = inv[:, 0], inv[:, 1]
    ta = p1[:, None] * inv1
    tb = p2[:, None] * inv1
    tc = q1[:, None] * inv2
    td = q2[:, None] * inv2
    near = np.maximum(np.minimum(ta, tb), np.minimum(tc, td))
    far = np.minimum(np.maximum(ta, tb), np.maximum(tc, td))
    return near, far


def curve_polygon(a: float, b: float, cx: float, cy: float) -> np.ndarray:
    phi = np.linspace(0.0, 2.0 * np.pi, CURVE_VERTICES, endpoint=False)
    return np.stack([cx + a * np.cos(phi), cy + b * np.sin(phi)], axis=-1)

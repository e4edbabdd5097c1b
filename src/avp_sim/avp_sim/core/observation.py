"""Occlusion-aware observation model (paper §III-A), vectorised with numpy.

Paper §III-A: the ego has a compact, connected *base sensing region* Q0 (given in the ego frame);
at time t the sensing region Q_t is Q0 rotated by the ego heading and translated to the ego position.
The ego shoots ``n_ray`` rays; ray j is the shortest segment that starts at the ego position, points
in its direction and ends on the lot boundary dL, on the boundary of another vehicle dV_k, or on dQ_t,
whichever comes first. The ego observes every vehicle, spot and pedestrian that intersects a ray.
Spots are occupied iff some vehicle lies entirely inside them (V ⊆ S), and a vehicle is *static* iff
it lies inside some spot, *dynamic* otherwise (:func:`classify_world`).

Conventions and edge cases (all closed sets; "touching" counts):

* Ray j has world angle ``theta_ego + j * 2*pi/n_ray`` (reported wrapped to [-pi, pi)).
* Pedestrians never block rays; a pedestrian disc is seen iff its distance to some ray segment is
  <= its radius.
* The ego itself is not an obstacle: the caller passes only the *other* vehicles.
* If the ego position lies inside (or on the boundary of) another vehicle, every ray has range 0,
  ends at the ego position, and reports that vehicle as hit (the lowest index if several).
* If the ego position lies on the lot boundary dL (within 1e-9 m), every ray has range 0.
* If the ego position lies outside the lot, each ray stops at its first crossing of dL (entering the
  lot); rays that never cross dL stop on dQ_t or a vehicle as usual.
* Vehicle rectangles are given by their 4 corners (counter-clockwise from front-left, as produced by
  :func:`avp_world.geometry.rect_corners`); any parallelogram is handled exactly.
* The disc and the ellipse are intersected analytically (exact ranges); their ``region_polygon`` is
  only a 256-vertex drawing aid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from avp_world.geometry import rect_inside_rect, wrap_angle
from avp_world.lot import LotMap

SHAPES = ("disc", "rectangle", "ellipse", "polygon")
_ON_BOUNDARY_TOL = 1e-9  # m: an ego position this close to dL is "on" the boundary
_SEG_PARAM_TOL = 1e-12  # slack on the segment parameter so rays through polygon vertices never slip through
_CURVE_VERTICES = 256  # vertices of the drawing polygon of a disc / ellipse
_TINY = 1e-300  # replaces exact zeros in n.d so that parallel rays give +-inf slab bounds, never NaN


def _is_number(v: object) -> bool:
    return isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool | np.bool_)


# ------------------------------------------------------------------------------------------- config


@dataclass(frozen=True)
class SensorConfig:
    """The base sensing region Q0 and the ray count of the observation model (paper §III-A).

    Q0 is given in the ego frame (x forward along the heading, y to the left) and centred on
    ``offset``; Q_t is Q0 rotated by the ego heading and translated to the ego position.

    Attributes:
        n_ray: number of rays (paper n_ray), evenly spaced, ray 0 along the heading.
        shape: "disc" (``radius``), "rectangle" (``length`` along / ``width`` across the heading),
            "ellipse" (``semi_major`` along / ``semi_minor`` across the heading) or "polygon"
            (``vertices``, ego frame, shifted by ``offset`` too).
        offset: centre of the region in the ego frame (for a polygon: a shift of its vertices).
    Q0 must contain the ego origin in its interior. Call :meth:`validate` (``RayCaster`` does).
    """

    n_ray: int = 360
    shape: str = "disc"
    radius: float = 11.5
    length: float = 23.0
    width: float = 23.0
    semi_major: float = 11.5
    semi_minor: float = 11.5
    offset: tuple[float, float] = (0.0, 0.0)
    vertices: tuple[tuple[float, float], ...] = ()

    def validate(self) -> SensorConfig:
        """Check the config; raise ValueError naming the offending field. Returns ``self``."""
        n = self.n_ray
        if not isinstance(n, int | np.integer) or isinstance(n, bool | np.bool_) or n < 1:
            raise ValueError(f"SensorConfig.n_ray: must be an integer >= 1, got {n!r}")
        if not isinstance(self.shape, str) or self.shape not in SHAPES:
            raise ValueError(f"SensorConfig.shape: must be one of {SHAPES}, got {self.shape!r}")
        off = self.offset
        if (
            not isinstance(off, tuple | list | np.ndarray)
            or len(off) != 2
            or not all(_is_number(c) and math.isfinite(c) for c in off)
        ):
            raise ValueError(f"SensorConfig.offset: expected two finite numbers (x, y), got {off!r}")
        ox, oy = float(off[0]), float(off[1])

        def positive(name: str) -> float:
            v = getattr(self, name)
            if not _is_number(v) or not math.isfinite(v) or v <= 0:
                raise ValueError(f"SensorConfig.{name}: must be a finite number > 0, got {v!r}")
            return float(v)

        where = "the ego origin (0, 0) does not lie in the interior of the sensing region"
        if self.shape == "disc":
            r = positive("radius")
            if math.hypot(ox, oy) >= r:
                raise ValueError(f"SensorConfig.offset: {where} (disc radius {r} centred at {off!r})")
        elif self.shape == "rectangle":
            length, width = positive("length"), positive("width")
            if abs(ox) >= 0.5 * length or abs(oy) >= 0.5 * width:
                raise ValueError(
                    f"SensorConfig.offset: {where} (rectangle {length} x {width} centred at {off!r})"
                )
        elif self.shape == "ellipse":
            a, b = positive("semi_major"), positive("semi_minor")
            if (ox / a) ** 2 + (oy / b) ** 2 >= 1.0:
                raise ValueError(f"SensorConfig.offset: {where} (ellipse {a} x {b} centred at {off!r})")
        else:
            self._validate_polygon(ox, oy, where)
        return self

    def _validate_polygon(self, ox: float, oy: float, where: str) -> None:
        from shapely.geometry import Point, Polygon

        verts = self.vertices
        try:
            arr = np.array(verts, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(
                f"SensorConfig.vertices: expected a sequence of (x, y) pairs, got {verts!r}"
            ) from None
        if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 3:
            raise ValueError(f"SensorConfig.vertices: expected >= 3 (x, y) pairs, got {verts!r}")
        if not np.isfinite(arr).all():
            raise ValueError("SensorConfig.vertices: all coordinates must be finite")
        poly = Polygon(arr + [ox, oy])
        if not poly.is_valid or poly.area <= 0:
            raise ValueError("SensorConfig.vertices: not a simple polygon with positive area")
        if not poly.contains(Point(0.0, 0.0)):
            raise ValueError(f"SensorConfig.vertices: {where} (vertices shifted by offset {self.offset!r})")


# ------------------------------------------------------------------------------------------ results


@dataclass(frozen=True, eq=False)
class RayScan:
    """One observation (paper §III-A): the rays and what they touched.

    Attributes:
        origin: (2,) ego position the rays leave from.
        angles: (n_ray,) world angles of the rays, wrapped to [-pi, pi).
        ranges: (n_ray,) ray lengths (>= 0).
        endpoints: (n_ray, 2) ray end points ``origin + range * (cos, sin)``.
        hit_vehicle: (n_ray,) int, index into the vehicle array of the vehicle the ray ends on, else -1.
        seen_vehicles: (N,) bool, vehicles touched by some ray.
        seen_spots: (n_spots,) bool, spots (closed rectangles) that intersect some ray segment.
        seen_pedestrians: (P,) bool, pedestrian discs within their radius of some ray segment.
    """

    origin: np.ndarray
    angles: np.ndarray
    ranges: np.ndarray
    endpoints: np.ndarray
    hit_vehicle: np.ndarray
    seen_vehicles: np.ndarray
    seen_spots: np.ndarray
    seen_pedestrians: np.ndarray


# ----------------------------------------------------------------------------------------- helpers


def _ray_polyline_t(
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
    ok = (denom != 0.0) & (t >= t_min) & (s >= -_SEG_PARAM_TOL) & (s <= 1.0 + _SEG_PARAM_TOL)
    return np.where(ok, t, np.inf).min(axis=1)


def _point_segment_dist(seg_a: np.ndarray, seg_b: np.ndarray) -> np.ndarray:
    """(M,) distance from the origin to segments given relative to it."""
    e = seg_b - seg_a
    ee = np.maximum((e * e).sum(-1), 1e-300)
    s = np.clip(-(seg_a * e).sum(-1) / ee, 0.0, 1.0)
    q = seg_a + s[:, None] * e
    return np.sqrt((q * q).sum(-1))


def _slabs(rel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
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


def _slab_interval(
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
    nd[nd == 0.0] = _TINY
    inv = (1.0 / nd).reshape(k, 2, -1)
    inv1, inv2 = inv[:, 0], inv[:, 1]
    ta = p1[:, None] * inv1
    tb = p2[:, None] * inv1
    tc = q1[:, None] * inv2
    td = q2[:, None] * inv2
    near = np.maximum(np.minimum(ta, tb), np.minimum(tc, td))
    far = np.minimum(np.maximum(ta, tb), np.maximum(tc, td))
    return near, far


def _curve_polygon(a: float, b: float, cx: float, cy: float) -> np.ndarray:
    phi = np.linspace(0.0, 2.0 * np.pi, _CURVE_VERTICES, endpoint=False)
    return np.stack([cx + a * np.cos(phi), cy + b * np.sin(phi)], axis=-1)


# ------------------------------------------------------------------------------------------ caster


class RayCaster:
    """Ray-casting observation model of paper §III-A for one lot and one sensor.

    Everything static is precomputed here: the lot boundary segments, the spot rectangles in slab
    form, the ray directions in the ego frame, Q0 as a polygon, and - because the rays are fixed in the
    ego frame - the exact distance ``region_range[j]`` from the ego to dQ0 along every ray.
    """

    def __init__(self, lot: LotMap, config: SensorConfig | None = None) -> None:
        self.lot = lot
        self.config = (config if config is not None else SensorConfig()).validate()
        cfg = self.config
        n = int(cfg.n_ray)
        self.n_ray = n
        self.ray_offsets = np.arange(n, dtype=float) * (2.0 * np.pi / n)  # ego-frame ray angles
        self.ray_dirs_ego = np.stack([np.cos(self.ray_offsets), np.sin(self.ray_offsets)], axis=-1)

        ox, oy = float(cfg.offset[0]), float(cfg.offset[1])
        d = self.ray_dirs_ego
        if cfg.shape == "disc":
            r = float(cfg.radius)
            if ox == 0.0 and oy == 0.0:
                rng = np.full(n, r)
            else:
                b = d[:, 0] * ox + d[:, 1] * oy
                rng = b + np.sqrt(b * b - (ox * ox + oy * oy) + r * r)
            self.region_polygon = _curve_polygon(r, r, ox, oy)
        elif cfg.shape == "ellipse":
            a, b = float(cfg.semi_major), float(cfg.semi_minor)
            qa = (d[:, 0] / a) ** 2 + (d[:, 1] / b) ** 2
            qb = -2.0 * (d[:, 0] * ox / (a * a) + d[:, 1] * oy / (b * b))
            qc = (ox / a) ** 2 + (oy / b) ** 2 - 1.0  # < 0: the origin is inside
            sq = np.sqrt(qb * qb - 4.0 * qa * qc)
            with np.errstate(divide="ignore", invalid="ignore"):
                rng = np.where(qb <= 0.0, (-qb + sq) / (2.0 * qa), 2.0 * qc / (-qb - sq))
            self.region_polygon = _curve_polygon(a, b, ox, oy)
        else:
            if cfg.shape == "rectangle":
                hl, hw = 0.5 * float(cfg.length), 0.5 * float(cfg.width)
                poly = np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]]) + [ox, oy]
            else:
                poly = np.array(cfg.vertices, dtype=float) + [ox, oy]
            rng = _ray_polyline_t(d, poly, np.roll(poly, -1, axis=0))
            self.region_polygon = poly
        self.region_range = np.asarray(rng, dtype=float)  # (n,) exact distance to dQ0 along each ray
        if not np.all(np.isfinite(self.region_range) & (self.region_range > 0)):
            raise ValueError("SensorConfig: sensing region gives a non-positive range on some ray")
        self.max_range = float(self.region_range.max())

        self._boundary_a = np.asarray(lot.boundary, dtype=float)
        self._boundary_b = np.roll(self._boundary_a, -1, axis=0)

        sc = np.asarray(lot.spot_corners, dtype=float).reshape(-1, 4, 2)
        self.n_spots = sc.shape[0]
        self._spot_center = sc.mean(axis=1)
        self._spot_brad = 0.5 * np.maximum(
            np.linalg.norm(sc[:, 0] - sc[:, 2], axis=-1), np.linalg.norm(sc[:, 1] - sc[:, 3], axis=-1)
        )
        normals, p1, p2, q1, q2 = _slabs(sc)  # world-frame slab offsets (origin at the world origin)
        self._spot_normals = normals.reshape(-1, 2, 2)
        self._spot_pq = np.stack([p1, p2, q1, q2], axis=-1)  # (S, 4)

    # -------------------------------------------------------------------------------------- api

    def region_world(self, ego_pose: np.ndarray) -> np.ndarray:
        """Q_t as a world-frame polygon (drawing aid; disc/ellipse approximated)."""
        x, y, th = (float(v) for v in np.asarray(ego_pose, dtype=float)[:3])
        c, s = math.cos(th), math.sin(th)
        p = self.region_polygon
        return np.stack([x + c * p[:, 0] - s * p[:, 1], y + s * p[:, 0] + c * p[:, 1]], axis=-1)

    def cast(
        self,
        ego_pose: np.ndarray,
        vehicle_corners: np.ndarray,
        ped_centers: np.ndarray | None = None,
        ped_radii: np.ndarray | None = None,
    ) -> RayScan:
        """Cast the rays of paper §III-A from ``ego_pose``.

        Args:
            ego_pose: (3,) ego (x, y, theta).
            vehicle_corners: (N, 4, 2) corners of the *other* vehicles (not the ego).
            ped_centers: (P, 2) pedestrian centres; ped_radii: (P,) radii (pedestrians never block).
        Returns:
            A :class:`RayScan`.
        """
        pose = np.asarray(ego_pose, dtype=float)
        ox, oy, th = float(pose[0]), float(pose[1]), float(pose[2])
        origin = np.array([ox, oy])
        c, s = math.cos(th), math.sin(th)
        de = self.ray_dirs_ego
        dirs = np.empty_like(de)
        dirs[:, 0] = c * de[:, 0] - s * de[:, 1]
        dirs[:, 1] = s * de[:, 0] + c * de[:, 1]
        n = self.n_ray
        r_max = self.max_range

        # --- the sensing region and the lot boundary
        ranges = self.region_range.copy()
        ba = self._boundary_a - origin
        bb = self._boundary_b - origin
        bdist = _point_segment_dist(ba, bb)
        if bdist.min() <= _ON_BOUNDARY_TOL:
            ranges[:] = 0.0
        else:
            near_b = bdist <= r_max
            if near_b.any():
                np.minimum(ranges, _ray_polyline_t(dirs, ba[near_b], bb[near_b]), out=ranges)

        # --- other vehicles (slab test per ray x vehicle, after a bounding-radius prune)
        vc = np.asarray(vehicle_corners, dtype=float).reshape(-1, 4, 2)
        n_veh = vc.shape[0]
        hit_vehicle = np.full(n, -1, dtype=np.int64)
        seen_vehicles = np.zeros(n_veh, dtype=bool)
        if n_veh:
            rel = vc - origin
            cen = 0.5 * (rel[:, 0] + rel[:, 2])
            half_diag = 0.5 * np.sqrt(
                np.maximum(((rel[:, 0] - rel[:, 2]) ** 2).sum(-1), ((rel[:, 1] - rel[:, 3]) ** 2).sum(-1))
            )
            keep = np.flatnonzero(np.sqrt((cen * cen).sum(-1)) - half_diag <= r_max)
            if keep.size:
                normals, p1, p2, q1, q2 = _slabs(rel[keep])
                near, far = _slab_interval(normals, p1, p2, q1, q2, dirs)
                t_veh = np.where((near <= far) & (far >= 0.0), np.maximum(near, 0.0), np.inf)  # (K, n)
                k_first = t_veh.argmin(axis=0)
                t_first = t_veh[k_first, np.arange(n)]
                is_hit = t_first <= ranges
                ranges = np.where(is_hit, t_first, ranges)
                hit_vehicle[is_hit] = keep[k_first[is_hit]]
                seen_vehicles[hit_vehicle[is_hit]] = True

        endpoints = origin + ranges[:, None] * dirs
        reach = float(ranges.max()) if n else 0.0

        # --- spots: a closed rectangle is seen iff it meets some ray segment [0, range]
        seen_spots = np.zeros(self.n_spots, dtype=bool)
        if self.n_spots:
            sc_rel = self._spot_center - origin
            cand = np.flatnonzero(np.sqrt((sc_rel * sc_rel).sum(-1)) - self._spot_brad <= reach)
            if cand.size:
                nrm = self._spot_normals[cand]  # (K, 2, 2)
                no = nrm @ origin  # (K, 2)
                pq = self._spot_pq[cand]
                near, far = _slab_interval(
                    nrm.reshape(-1, 2),
                    pq[:, 0] - no[:, 0],
                    pq[:, 1] - no[:, 0],
                    pq[:, 2] - no[:, 1],
                    pq[:, 3] - no[:, 1],
                    dirs,
                )
                meets = (near <= far) & (far >= 0.0) & (near <= ranges)
                seen_spots[cand] = meets.any(axis=1)

        # --- pedestrians: distance from each disc centre to each ray segment
        if ped_centers is None:
            pc = np.zeros((0, 2))
        else:
            pc = np.asarray(ped_centers, dtype=float).reshape(-1, 2)
        pr = np.zeros(0) if ped_radii is None else np.asarray(ped_radii, dtype=float).reshape(-1)
        if pr.shape[0] != pc.shape[0]:
            raise ValueError(f"cast: ped_radii has {pr.shape[0]} entries for {pc.shape[0]} pedestrians")
        seen_peds = np.zeros(pc.shape[0], dtype=bool)
        if pc.shape[0]:
            prel = pc - origin
            pd2 = (prel * prel).sum(-1)
            cand = np.flatnonzero(np.sqrt(pd2) <= reach + pr)
            if cand.size:
                proj = prel[cand] @ dirs.T  # (K, n)
                t = np.clip(proj, 0.0, ranges)
                dist2 = pd2[cand, None] - 2.0 * t * proj + t * t
                seen_peds[cand] = (dist2 <= (pr[cand] ** 2)[:, None]).any(axis=1)

        return RayScan(
            origin=origin,
            angles=np.asarray(wrap_angle(th + self.ray_offsets)),
            ranges=ranges,
            endpoints=endpoints,
            hit_vehicle=hit_vehicle,
            seen_vehicles=seen_vehicles,
            seen_spots=seen_spots,
            seen_pedestrians=seen_peds,
        )


# ------------------------------------------------------------------------------------- classifier


def classify_world(
    lot: LotMap, vehicle_corners: np.ndarray, tol: float = 1e-6
) -> tuple[np.ndarray, np.ndarray]:
    """Occupied spots and static vehicles (paper §III-A).

    A spot S_i is occupied iff some vehicle lies entirely inside it (V_k ⊆ S_i); a vehicle is static iff
    it lies inside some spot, dynamic otherwise.

    Args:
        lot: the lot map.
        vehicle_corners: (N, 4, 2) corners of the vehicles to classify.
        tol: slack of the containment test as a fraction of the spot's side lengths.
    Returns:
        spot_occupied (n_spots,) bool and vehicle_spot (N,) int (the containing spot's row in the lot's
        spot arrays, -1 for a dynamic vehicle; the lowest row if spots overlap).
    """
    vc = np.asarray(vehicle_corners, dtype=float).reshape(-1, 4, 2)
    sc = np.asarray(lot.spot_corners, dtype=float).reshape(-1, 4, 2)
    if vc.shape[0] == 0 or sc.shape[0] == 0:
        return np.zeros(sc.shape[0], dtype=bool), np.full(vc.shape[0], -1, dtype=np.int64)
    inside = rect_inside_rect(vc[:, None], sc[None, :], tol=tol)  # (N, S)
    spot_occupied = inside.any(axis=0)
    vehicle_spot = np.where(inside.any(axis=1), inside.argmax(axis=1), -1).astype(np.int64)
    return spot_occupied, vehicle_spot


__all__ = ["SHAPES", "RayCaster", "RayScan", "SensorConfig", "classify_world"]

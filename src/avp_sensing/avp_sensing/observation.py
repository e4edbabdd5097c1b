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

from avp_sensing.occupancy import classify_world
from avp_sensing.ray_geometry import curve_polygon, point_segment_dist, ray_polyline_t, slab_interval, slabs
from avp_world.geometry import wrap_angle
from avp_world.lot import LotMap

SHAPES = ("disc", "rectangle", "ellipse", "polygon")
_ON_BOUNDARY_TOL = 1e-9  # m: an ego position this close to dL is "on" the boundary


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
            self.region_polygon = curve_polygon(r, r, ox, oy)
        elif cfg.shape == "ellipse":
            a, b = float(cfg.semi_major), float(cfg.semi_minor)
            qa = (d[:, 0] / a) ** 2 + (d[:, 1] / b) ** 2
            qb = -2.0 * (d[:, 0] * ox / (a * a) + d[:, 1] * oy / (b * b))
            qc = (ox / a) ** 2 + (oy / b) ** 2 - 1.0  # < 0: the origin is inside
            sq = np.sqrt(qb * qb - 4.0 * qa * qc)
            with np.errstate(divide="ignore", invalid="ignore"):
                rng = np.where(qb <= 0.0, (-qb + sq) / (2.0 * qa), 2.0 * qc / (-qb - sq))
            self.region_polygon = curve_polygon(a, b, ox, oy)
        else:
            if cfg.shape == "rectangle":
                hl, hw = 0.5 * float(cfg.length), 0.5 * float(cfg.width)
                poly = np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]]) + [ox, oy]
            else:
                poly = np.array(cfg.vertices, dtype=float) + [ox, oy]
            rng = ray_polyline_t(d, poly, np.roll(poly, -1, axis=0))
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
        normals, p1, p2, q1, q2 = slabs(sc)  # world-frame slab offsets (origin at the world origin)
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
        ranges = self._region_and_boundary(origin, dirs)
        ranges, hit_vehicle, seen_vehicles = self._vehicles(origin, dirs, ranges, vehicle_corners)
        reach = float(ranges.max()) if self.n_ray else 0.0
        return RayScan(
            origin=origin,
            angles=np.asarray(wrap_angle(th + self.ray_offsets)),
            ranges=ranges,
            endpoints=origin + ranges[:, None] * dirs,
            hit_vehicle=hit_vehicle,
            seen_vehicles=seen_vehicles,
            seen_spots=self._spots_met(origin, dirs, ranges, reach),
            seen_pedestrians=self._pedestrians_met(origin, dirs, ranges, reach, ped_centers, ped_radii),
        )

    def _region_and_boundary(self, origin: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """(n_ray,) ranges to dQ_t or, where nearer, the lot boundary dL (all 0 on dL)."""
        ranges = self.region_range.copy()
        ba = self._boundary_a - origin
        bb = self._boundary_b - origin
        bdist = point_segment_dist(ba, bb)
        if bdist.min() <= _ON_BOUNDARY_TOL:
            ranges[:] = 0.0
        else:
            near_b = bdist <= self.max_range
            if near_b.any():
                np.minimum(ranges, ray_polyline_t(dirs, ba[near_b], bb[near_b]), out=ranges)
        return ranges

    def _vehicles(self, origin: np.ndarray, dirs: np.ndarray, ranges: np.ndarray, vehicle_corners: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rays cut at the first vehicle they meet (slab test per ray x vehicle, after a bounding-radius prune):
        (ranges, hit vehicle index per ray or -1, seen flag per vehicle)."""
        n = self.n_ray
        vc = np.asarray(vehicle_corners, dtype=float).reshape(-1, 4, 2)
        n_veh = vc.shape[0]
        hit_vehicle = np.full(n, -1, dtype=np.int64)
        seen_vehicles = np.zeros(n_veh, dtype=bool)
        if not n_veh:
            return ranges, hit_vehicle, seen_vehicles
        rel = vc - origin
        cen = 0.5 * (rel[:, 0] + rel[:, 2])
        half_diag = 0.5 * np.sqrt(
            np.maximum(((rel[:, 0] - rel[:, 2]) ** 2).sum(-1), ((rel[:, 1] - rel[:, 3]) ** 2).sum(-1))
        )
        keep = np.flatnonzero(np.sqrt((cen * cen).sum(-1)) - half_diag <= self.max_range)
        if keep.size:
            normals, p1, p2, q1, q2 = slabs(rel[keep])
            near, far = slab_interval(normals, p1, p2, q1, q2, dirs)
            t_veh = np.where((near <= far) & (far >= 0.0), np.maximum(near, 0.0), np.inf)  # (K, n)
            k_first = t_veh.argmin(axis=0)
            t_first = t_veh[k_first, np.arange(n)]
            is_hit = t_first <= ranges
            ranges = np.where(is_hit, t_first, ranges)
            hit_vehicle[is_hit] = keep[k_first[is_hit]]
            seen_vehicles[hit_vehicle[is_hit]] = True
        return ranges, hit_vehicle, seen_vehicles

    def _spots_met(self, origin: np.ndarray, dirs: np.ndarray, ranges: np.ndarray, reach: float) -> np.ndarray:
        """(n_spots,) seen flags: a closed spot rectangle is seen iff it meets some ray segment [0, range]."""
        seen_spots = np.zeros(self.n_spots, dtype=bool)
        if not self.n_spots:
            return seen_spots
        sc_rel = self._spot_center - origin
        cand = np.flatnonzero(np.sqrt((sc_rel * sc_rel).sum(-1)) - self._spot_brad <= reach)
        if cand.size:
            nrm = self._spot_normals[cand]  # (K, 2, 2)
            no = nrm @ origin  # (K, 2)
            pq = self._spot_pq[cand]
            near, far = slab_interval(
                nrm.reshape(-1, 2),
                pq[:, 0] - no[:, 0],
                pq[:, 1] - no[:, 0],
                pq[:, 2] - no[:, 1],
                pq[:, 3] - no[:, 1],
                dirs,
            )
            meets = (near <= far) & (far >= 0.0) & (near <= ranges)
            seen_spots[cand] = meets.any(axis=1)
        return seen_spots

    @staticmethod
    def _pedestrians_met(origin: np.ndarray, dirs: np.ndarray, ranges: np.ndarray, reach: float,
                         ped_centers: np.ndarray | None, ped_radii: np.ndarray | None) -> np.ndarray:
        """(P,) seen flags: a pedestrian disc is seen iff some ray segment comes within its radius."""
        pc = np.zeros((0, 2)) if ped_centers is None else np.asarray(ped_centers, dtype=float).reshape(-1, 2)
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
        return seen_peds


__all__ = ["SHAPES", "RayCaster", "RayScan", "SensorConfig", "classify_world"]

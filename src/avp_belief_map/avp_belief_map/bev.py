"""BEV reconstruction with the belief map (paper §V-B) for one observed dynamic vehicle V_k.

The ParkPredict+ intent CNN (§V-A) needs a semantic bird's-eye view I_k,i of a 40 m square around V_k,
but the ego only observes part of it. We rebuild it from what is known: the map (roads, spots), the
observed vehicles with their histories, and the belief b~_t of eq. (7) for everything unobserved.

Image (as ParkPredict+, reference sheet §1.1): one RGB uint8 image centred on V_k and rotated so that its
heading points along +column and its left along +row, i.e. for a world point p and V_k's pose (x, y, theta)

    col = ((p - (x, y)) . (cos theta, sin theta)) / m_per_px + size_px / 2
    row = ((p - (x, y)) . (-sin theta, cos theta)) / m_per_px + size_px / 2

(integer coordinates are pixel centres). Drawing order and colours (sheet §1.1):

1. black background, drivable area (roads) grey (193, 193, 193);
2. empty spots green (0, 255, 0), shrunk by 0.3 m on every side: spots with b~ < beta whose centre window
   (+-0.8 m, ParkPredict+'s occupancy test) is not covered by another observed vehicle;
3. blue (0, 0, 255): observed static vehicles, and a default car l_def x w_def (4.97 x 1.86 m, §VI-A) on
   every *unobserved* spot with b~ >= beta (§V-B) — never on an observed spot;
4. yellow (255, 255, 0): the other observed dynamic vehicles and the ego vehicle (just another observed
   vehicle here), with a fading history trail;
5. red (255, 0, 0): V_k itself with its trail.

Trails (ParkPredict+ ``_color_transition``): ``trail_steps`` past poses ``trail_period`` apart (10 x 0.4 s =
t_hist = 4 s, as the intent training data), the oldest at half intensity, step i (0 = oldest) at
(0.5 + 0.5 i / (2 steps)) of the colour, the current pose at full colour.

Candidates (§V-B): spots with b~ < beta within V_k's BEV (centre inside the crop) that are drawn green,
i.e. whose +-0.8 m centre window meets no current footprint of another observed vehicle (or the ego);
V_k's own footprint does not count unless ``target_blocks_spot`` (ParkPredict+'s mask also held the
vehicle itself, which hides the spot a car is already entering). Image I_k,i is a copy with spot i's green
rectangle filled purple (128, 0, 128); I_k,0 is unmarked.

:meth:`BEVRenderer.render_all` renders all vehicles of one observation sharing the world-frame work
(footprints, trails, which spots are covered) in a :class:`BEVScene`; drawing is exact to the order above
(a trail footprint identical to the next one is skipped: it would be overdrawn entirely).

Exploration points (§V-A, §V-D): poses on road centre lines C_j with heading theta_Rj or theta_Rj + pi.
Default ("circle"): the intersections of the centre lines with a circle of ``exploration_radius`` (11.5 m,
the paper's sensing radius) around V_k — the paper's definition for the ego (§V-D) applied to V_k, with
the heading pointing away from V_k along the road. Alternative ("square"): the crossings of the centre
lines with the boundary of the BEV square, which is what ParkPredict+ collects (sheet §1.6), but on the
paper's 43 x 41.5 m lot a 40 m square around a car in the lot holds nearly every centre line, so it
usually yields no point at all. Points are ranked as ParkPredict+ ranks lanes: best heading alignment
(cosine) first, then shortest distance.

Resolution: ParkPredict+ used 400 x 400 px at 0.1 m/px; the default here is 100 x 100 at 0.4 m/px — the
same 40 m field of view at the resolution ParkPredict+'s own trajectory model resizes these crops to
(sheet §2.1), 16x fewer pixels for the CNN (a 2.75 m spot is ~7 px wide, a 1.86 m car ~5 px), which is
what makes the per-step budget (bench/bench_perception.py) reachable on a CPU.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from avp_belief_map.exploration import (  # noqa: F401 - re-exported
    exploration_points_circle,
    exploration_points_square,
    rank_exploration_points,
)
from avp_world.geometry import rect_corners, rects_overlap
from avp_world.lot import LotMap
from avp_world.types import Observation, ObservedVehicle

COLOR_BACKGROUND = (0, 0, 0)
COLOR_DRIVABLE = (193, 193, 193)
COLOR_EMPTY_SPOT = (0, 255, 0)
COLOR_STATIC = (0, 0, 255)
COLOR_DYNAMIC = (255, 255, 0)
COLOR_TARGET = (255, 0, 0)
COLOR_CANDIDATE = (128, 0, 128)  # PIL "purple"

STATIC_GROUP = -(2**62)  # group id of observed static vehicles in a scene
EGO_GROUP = -(2**62) + 1  # group id of the ego's trail
_SHIFT = 4  # cv2 fixed-point bits: polygon vertices at 1/16 px
_SCALE = float(1 << _SHIFT)
EXPLORATION_SHAPES = ("circle", "square")


@dataclass(frozen=True)
class BEVConfig:
    """Parameters of the BEV reconstruction (§V-B; defaults from §VI-A and ParkPredict+)."""

    size_px: int = 100  # image is size_px x size_px
    m_per_px: float = 0.4  # 40 m field of view as ParkPredict+ (400 px x 0.1 m/px)
    beta: float = 0.5  # b >= beta: believed occupied (§VI-A)
    default_length: float = 4.97  # l_def (§VI-A)
    default_width: float = 1.86  # w_def (§VI-A)
    spot_margin: float = 0.3  # empty spots are drawn shrunk by this on every side (ParkPredict+)
    spot_clear_halfwidth: float = 0.8  # a spot whose +-0.8 m centre window meets a vehicle is not empty
    target_blocks_spot: bool = False  # True: V_k's own footprint also makes a spot non-empty (ParkPredict+)
    trail_steps: int = 10  # past poses drawn per vehicle
    trail_period: float = 0.4  # s between trail poses (10 x 0.4 s = t_hist)
    exploration_shape: str = "circle"  # "circle" or "square" (see module docstring)
    exploration_radius: float = 11.5  # m, radius of the exploration circle

    def validate(self) -> BEVConfig:
        if int(self.size_px) != self.size_px or self.size_px < 8:
            raise ValueError(f"size_px must be an integer >= 8, got {self.size_px!r}")
        for name in ("m_per_px", "default_length", "default_width", "trail_period", "exploration_radius"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {v!r}")
        if not 0.0 <= self.beta <= 1.0:
            raise ValueError(f"beta must be in [0, 1], got {self.beta!r}")
        if self.spot_margin < 0 or self.spot_clear_halfwidth < 0:
            raise ValueError("spot_margin and spot_clear_halfwidth must be >= 0")
        if int(self.trail_steps) != self.trail_steps or self.trail_steps < 0:
            raise ValueError(f"trail_steps must be an integer >= 0, got {self.trail_steps!r}")
        if self.exploration_shape not in EXPLORATION_SHAPES:
            raise ValueError(f"exploration_shape must be one of {EXPLORATION_SHAPES}, got {self.exploration_shape!r}")
        return self

    @property
    def extent_m(self) -> float:
        """Side of the BEV square in metres (40 m by default)."""
        return self.size_px * self.m_per_px


@dataclass(frozen=True)
class VehicleBEV:
    """The reconstructed BEV of one observed dynamic vehicle V_k and its intent candidates."""

    vehicle_id: int
    pose: np.ndarray  # (3,) V_k's pose, the crop centre
    speed: float  # m/s from the last two history poses
    image: np.ndarray  # (H, W, 3) uint8: I_k,0, no spot marked
    candidate_idx: np.ndarray  # (K,) lot rows of I_can,k
    candidate_spot_ids: np.ndarray  # (K,) lot spot ids of I_can,k
    candidate_images: np.ndarray  # (K, H, W, 3) uint8: I_k,i with candidate i marked purple
    candidate_boxes: np.ndarray  # (K, 4) int64 (row0, row1, col0, col1): inclusive box of the marked pixels
    exploration_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (Q, 3) ranked

    def images(self) -> np.ndarray:
        """(K + 1, H, W, 3): I_k,0 first, then the marked images in candidate order."""
        return np.concatenate([self.image[None], self.candidate_images], axis=0)


@dataclass(frozen=True)
class BEVScene:
    """World-frame footprints of one observation shared by the BEVs of all its dynamic vehicles."""

    b: np.ndarray  # b~ (N_S,)
    observed: np.ndarray  # (N_S,) bool
    polys: np.ndarray  # (M, 4, 2): static vehicles, then each trail (oldest first), the ego's trail last
    groups: np.ndarray  # (M,) vehicle id of each footprint (STATIC_GROUP / EGO_GROUP)
    hidden: np.ndarray  # (M,) footprint identical to the next one of its trail
    n_static: int
    trails: dict[int, tuple[int, int]]  # group -> rows [start, end) of its trail
    owners: np.ndarray  # (C,) group of each current footprint
    covered: np.ndarray  # (N_S, C): the spot's +-0.8 m centre window meets current footprint c
    dt: float


# ------------------------------------------------------------------------------------- transforms


def world_to_pixel(points: np.ndarray, pose: np.ndarray, size_px: int, m_per_px: float) -> np.ndarray:
    """(..., 2) world points -> (..., 2) continuous (col, row) pixel coordinates of the crop at ``pose``."""
    p = np.asarray(points, dtype=float)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    rot = np.array([[c, -s], [s, c]])  # d @ rot = (d . (c, s), d . (-s, c))
    return (p - np.asarray(pose[:2], dtype=float)) @ rot / m_per_px + 0.5 * size_px


def pixel_to_world(pixels: np.ndarray, pose: np.ndarray, size_px: int, m_per_px: float) -> np.ndarray:
    """Inverse of :func:`world_to_pixel` (ParkPredict+: ground = R(theta) (pixel * res - half) + pos)."""
    q = (np.asarray(pixels, dtype=float) - 0.5 * size_px) * m_per_px
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return q @ np.array([[c, s], [-s, c]]) + np.asarray(pose[:2], dtype=float)


def speed_from_history(history: np.ndarray, dt: float) -> float:
    """Predicted speed v_hat = |p_t - p_t-dt| / dt from the last two history poses (0 with one pose)."""
    h = np.asarray(history, dtype=float)
    if len(h) < 2 or dt <= 0:
        return 0.0
    return float(math.hypot(h[-1, 0] - h[-2, 0], h[-1, 1] - h[-2, 1]) / dt)


def trail_colors(color: tuple[int, int, int], steps: int) -> list[tuple[int, int, int]]:
    """ParkPredict+ ``_color_transition``: colours of the ``steps`` past poses (oldest first), then the current."""
    out = []
    for i in range(steps):
        f = 0.5 + 0.5 * i / (2.0 * steps)
        out.append(tuple(int(f * c) for c in color))
    out.append(tuple(int(c) for c in color))
    return out


def trail_poses(history: np.ndarray, dt: float, steps: int, period: float) -> np.ndarray:
    """Past poses t - steps*period, ..., t - period (those the history covers) and the current pose, oldest first."""
    h = np.asarray(history, dtype=float).reshape(-1, 3)
    stride = max(1, int(round(period / dt))) if dt > 0 else 1
    idx = [len(h) - 1 - stride * j for j in range(steps, 0, -1) if len(h) - 1 - stride * j >= 0]
    return h[idx + [len(h) - 1]]


def changed_boxes(images: np.ndarray, base: np.ndarray) -> np.ndarray:
    """(K, 4) int64 inclusive boxes (row0, row1, col0, col1) of the pixels where each image differs from
    ``base`` ((0, -1, 0, -1) for an unchanged image)."""
    if len(images) == 0:
        return np.zeros((0, 4), dtype=np.int64)
    ne = images != base[None]  # (K, H, W, 3)
    k, h, w = ne.shape[:3]
    rows = ne.reshape(k, h, -1).any(axis=2)  # reductions over contiguous blocks (fast), not over the 3 channels
    cols = ne.any(axis=1).any(axis=2)
    r0, r1 = rows.argmax(axis=1), h - 1 - rows[:, ::-1].argmax(axis=1)
    c0, c1 = cols.argmax(axis=1), w - 1 - cols[:, ::-1].argmax(axis=1)
    boxes = np.stack([r0, r1, c0, c1], axis=1).astype(np.int64).reshape(-1, 4)
    boxes[~rows.any(axis=1)] = (0, -1, 0, -1)
    return boxes


# ------------------------------------------------------------------------------------------- render


class BEVRenderer:
    """Draws the reconstructed BEV of observed dynamic vehicles on one lot (§V-B).

    Everything that depends on the map only (road rectangles, shrunk spots, default cars, spot centre
    windows) is computed once here; :meth:`render` transforms all polygons of a crop with one matrix
    product and fills them with ``cv2.fillPoly`` / ``cv2.fillConvexPoly`` (no per-pixel Python loops).
    """

    def __init__(self, lot: LotMap, config: BEVConfig = BEVConfig()):
        self.lot = lot
        self.config = config.validate()
        cfg = self.config
        self.size = int(cfg.size_px)
        self.road_polys = lot.road_corners.copy()  # (R, 4, 2)
        m2 = 2.0 * cfg.spot_margin
        self.spot_polys = rect_corners(lot.spot_poses, lot.spot_dims[:, 0] - m2, lot.spot_dims[:, 1] - m2)
        self.default_cars = rect_corners(lot.spot_poses, cfg.default_length, cfg.default_width)
        w = 2.0 * cfg.spot_clear_halfwidth
        self.spot_windows = rect_corners(lot.spot_poses, w, w)
        self.spot_centers = lot.spot_poses[:, :2].copy()
        self._index = {int(s): k for k, s in enumerate(lot.spot_ids)}
        n_r, n_s = len(self.road_polys), lot.n_spots
        # one stacked array of map polygons: roads | shrunk spots | default cars
        self._map_polys = np.concatenate([self.road_polys, self.spot_polys, self.default_cars]).reshape(-1, 2)
        self._slices = (slice(0, n_r), slice(n_r, n_r + n_s), slice(n_r + n_s, n_r + 2 * n_s))
        self._yellow = trail_colors(COLOR_DYNAMIC, cfg.trail_steps)
        self._red = trail_colors(COLOR_TARGET, cfg.trail_steps)

    # ---------------------------------------------------------------- helpers
    def spot_rows(self, spot_ids: np.ndarray) -> np.ndarray:
        return np.fromiter((self._index[int(s)] for s in spot_ids), dtype=np.int64)

    def observed_mask(self, obs: Observation) -> np.ndarray:
        m = np.zeros(self.lot.n_spots, dtype=bool)
        m[self.spot_rows(obs.vacant_spot_ids)] = True
        m[self.spot_rows(obs.occupied_spot_ids)] = True
        return m

    def to_pixels(self, points: np.ndarray, pose: np.ndarray) -> np.ndarray:
        return world_to_pixel(points, pose, self.size, self.config.m_per_px)

    def _in_crop(self, pix: np.ndarray) -> np.ndarray:
        """Points (..., 2) in pixel coordinates that fall on the image (pixel footprints included)."""
        lo, hi = -0.5, self.size - 0.5
        return (pix[..., 0] >= lo) & (pix[..., 0] < hi) & (pix[..., 1] >= lo) & (pix[..., 1] < hi)

    def _visible(self, poly_pix: np.ndarray) -> np.ndarray:
        """(n, 4, 2) pixel polygons whose bounding box meets the image."""
        # corner by corner: 4.4 times faster than min/max over the axis of 4 on a busy lot (773 polygons a call)
        c = poly_pix
        lo = np.minimum(np.minimum(c[:, 0], c[:, 1]), np.minimum(c[:, 2], c[:, 3]))
        hi = np.maximum(np.maximum(c[:, 0], c[:, 1]), np.maximum(c[:, 2], c[:, 3]))
        return (hi[:, 0] >= -1) & (hi[:, 1] >= -1) & (lo[:, 0] <= self.size) & (lo[:, 1] <= self.size)

    @staticmethod
    def _fixed(poly_pix: np.ndarray) -> np.ndarray:
        return np.round(poly_pix * _SCALE).astype(np.int32)

    # ---------------------------------------------------------------- render
    def scene(self, obs: Observation, b_tilde: np.ndarray, observed: np.ndarray | None = None,
              ego_history: np.ndarray | None = None) -> BEVScene:
        """Everything the BEVs of one observation share, in world coordinates (see :meth:`render_all`)."""
        cfg = self.config
        b = np.asarray(b_tilde, dtype=float)
        if b.shape != (self.lot.n_spots,):
            raise ValueError(f"b_tilde must have shape ({self.lot.n_spots},), got {b.shape}")
        if observed is None:
            observed = self.observed_mask(obs)
        poses: list[np.ndarray] = []
        dims: list[tuple[float, float]] = []
        groups: list[int] = []
        trails: dict[int, tuple[int, int]] = {}

        def add(p: np.ndarray, length: float, width: float, group: int) -> None:
            p = p.reshape(-1, 3)
            if group != STATIC_GROUP:
                trails[group] = (len(dims), len(dims) + len(p))
            poses.append(p)
            dims.extend([(length, width)] * len(p))
            groups.extend([group] * len(p))

        for v in obs.vehicles:
            if v.is_static:
                add(np.asarray(v.pose, float), v.length, v.width, STATIC_GROUP)
        n_static = len(dims)
        for v in obs.vehicles:
            if not v.is_static:
                add(trail_poses(v.history, obs.dt, cfg.trail_steps, cfg.trail_period), v.length, v.width, int(v.id))
        ego_hist = np.asarray(obs.ego_pose, float)[None] if ego_history is None else np.asarray(ego_history, float)
        add(trail_poses(ego_hist, obs.dt, cfg.trail_steps, cfg.trail_period), obs.ego_length, obs.ego_width,
            EGO_GROUP)
        dims_a = np.array(dims, dtype=float)
        polys = rect_corners(np.concatenate(poses), dims_a[:, 0], dims_a[:, 1])
        g = np.array(groups, dtype=np.int64)
        # a footprint identical to the next one of the same trail is overdrawn entirely by it (standing still)
        hidden = np.zeros(len(g), dtype=bool)
        hidden[:-1] = (g[:-1] == g[1:]) & np.all(polys[:-1] == polys[1:], axis=(1, 2))
        # current footprints (static vehicles, last pose of every trail) and the spots they cover
        cur = np.concatenate([np.arange(n_static), [e - 1 for _, e in trails.values()]]).astype(np.int64)
        owners = g[cur]
        covered = np.zeros((self.lot.n_spots, len(cur)), dtype=bool)
        cand = np.nonzero(b < cfg.beta)[0]
        if len(cand):
            blockers = polys[cur]
            bc = blockers.mean(axis=1)
            br = np.linalg.norm(blockers[:, 0] - bc, axis=1)
            gap = np.linalg.norm(self.spot_centers[cand][:, None] - bc[None], axis=2)
            ii, jj = np.nonzero(gap <= br[None] + math.sqrt(2.0) * cfg.spot_clear_halfwidth + 1e-9)
            if len(ii):  # bounding-circle prefilter, then the exact separating-axis test
                hit = rects_overlap(self.spot_windows[cand[ii]], blockers[jj])
                covered[cand[ii[hit]], jj[hit]] = True
        return BEVScene(b, np.asarray(observed, dtype=bool), polys, g, hidden, n_static, trails, owners, covered,
                      obs.dt)

    def render(
        self,
        obs: Observation,
        vehicle: ObservedVehicle,
        b_tilde: np.ndarray,
        observed: np.ndarray | None = None,
        ego_history: np.ndarray | None = None,
    ) -> VehicleBEV:
        """Reconstruct I_k,0 and I_k,i (i in I_can,k) for observed dynamic vehicle ``vehicle`` (§V-B).

        Args:
            obs: the ego's observation at t.
            vehicle: V_k (one of ``obs.vehicles``; its history gives the trail and the speed).
            b_tilde: (N_S,) belief after eq. (7), in lot spot order.
            observed: (N_S,) bool, spots in I_vac,t or I_occ,t (computed from ``obs`` if None).
            ego_history: (H, 3) past ego poses at ``obs.dt`` ending with the current one, for the ego's trail
                (the observation carries only the current ego pose).
        """
        return self.render_all(obs, [vehicle], b_tilde, observed, ego_history)[0]

    def render_all(self, obs: Observation, vehicles: list[ObservedVehicle], b_tilde: np.ndarray,
                   observed: np.ndarray | None = None, ego_history: np.ndarray | None = None) -> list[VehicleBEV]:
        """:meth:`render` for several vehicles of one observation, sharing the world-frame work."""
        if not vehicles:
            return []
        sc = self.scene(obs, b_tilde, observed, ego_history)
        return [self._render(sc, v) for v in vehicles]

    def _render(self, sc: BEVScene, vehicle: ObservedVehicle) -> VehicleBEV:
        cfg = self.config
        size = self.size
        pose = np.asarray(vehicle.pose, dtype=float)
        vid = int(vehicle.id)
        if vid not in sc.trails:
            raise ValueError(f"vehicle {vid} is not an observed dynamic vehicle of this observation")
        img = np.zeros((size, size, 3), dtype=np.uint8)
        b = sc.b
        blocking = sc.owners != vid if not cfg.target_blocks_spot else np.ones(len(sc.owners), dtype=bool)
        empty = (b < cfg.beta) & ~(sc.covered[:, blocking].any(axis=1))

        # all polygons to pixels with one matrix product: roads | shrunk spots | default cars | vehicles
        pix = self.to_pixels(np.concatenate([self._map_polys, sc.polys.reshape(-1, 2)]), pose).reshape(-1, 4, 2)
        visible = self._visible(pix)
        fixed = self._fixed(pix)
        n_map = len(self._map_polys) // 4
        s_road, s_spot, s_car = self._slices

        # 1. drivable area (roads overlap at the corners: fill one by one, fillPoly is even-odd)
        for k in np.nonzero(visible[s_road])[0]:
            cv2.fillConvexPoly(img, fixed[s_road][k], COLOR_DRIVABLE, lineType=cv2.LINE_8, shift=_SHIFT)
        # 2. empty spots (disjoint rectangles: one call)
        green = empty & visible[s_spot]
        if green.any():
            cv2.fillPoly(img, fixed[s_spot][green], COLOR_EMPTY_SPOT, lineType=cv2.LINE_8, shift=_SHIFT)
        # 3. default cars on unobserved believed-occupied spots (disjoint: one call), never on observed spots
        believed = (b >= cfg.beta) & ~sc.observed & visible[s_car]
        if believed.any():
            cv2.fillPoly(img, fixed[s_car][believed], COLOR_STATIC, lineType=cv2.LINE_8, shift=_SHIFT)
        # 3. observed static vehicles (parked in distinct spots, disjoint: one call)
        veh_fixed, veh_vis = fixed[n_map:], visible[n_map:]
        ns = sc.n_static
        if veh_vis[:ns].any():
            cv2.fillPoly(img, veh_fixed[:ns][veh_vis[:ns]], COLOR_STATIC, lineType=cv2.LINE_8, shift=_SHIFT)
        # 4. the other dynamic vehicles and the ego: yellow trails; 5. V_k: red trail, last
        t0, t1 = sc.trails[vid]
        draw = veh_vis & ~sc.hidden
        draw[:ns] = False
        draw[t0:t1] = False
        for k in np.nonzero(draw)[0]:
            start, end = sc.trails[int(sc.groups[k])]
            cv2.fillConvexPoly(img, veh_fixed[k], self._yellow[len(self._yellow) - (end - k)],
                               lineType=cv2.LINE_8, shift=_SHIFT)
        for k in range(t0, t1):
            if veh_vis[k] and not sc.hidden[k]:
                cv2.fillConvexPoly(img, veh_fixed[k], self._red[len(self._red) - (t1 - k)], lineType=cv2.LINE_8,
                                   shift=_SHIFT)

        # candidates: empty (green) spots whose centre is inside the crop, each marked purple in a copy
        cand = np.nonzero(green & self._in_crop(self.to_pixels(self.spot_centers, pose)))[0]
        marked = np.repeat(img[None], len(cand), axis=0)
        spot_fixed = fixed[s_spot]
        for j, k in enumerate(cand):
            cv2.fillConvexPoly(marked[j], spot_fixed[k], COLOR_CANDIDATE, lineType=cv2.LINE_8, shift=_SHIFT)
        boxes = changed_boxes(marked, img)

        if cfg.exploration_shape == "circle":
            exp = exploration_points_circle(self.lot, pose, cfg.exploration_radius)
        else:
            exp = exploration_points_square(self.lot, pose, 0.5 * cfg.extent_m)
        return VehicleBEV(
            vehicle_id=vid,
            pose=pose.copy(),
            speed=speed_from_history(vehicle.history, sc.dt),
            image=img,
            candidate_idx=cand.astype(np.int64),
            candidate_spot_ids=self.lot.spot_ids[cand].astype(np.int64),
            candidate_images=marked,
            candidate_boxes=boxes,
            exploration_points=rank_exploration_points(pose, exp),
        )

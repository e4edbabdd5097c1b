"""Parking-lot maps (paper §II-A): spots, straight roads, entrance and the lot boundary L.

A lot is read from YAML (see ``maps/paper_lot.yaml`` for the format) and validated on load; any
problem raises :class:`LotMapError` with one line that names the file and the field.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from avp_world.geometry import rect_corners, rects_overlap
from avp_world.lot_scenario_block import parse_scenario_block

MAPS_DIR = Path(__file__).resolve().parent / "maps"


class LotMapError(ValueError):
    """A lot map file is malformed; the message names the file and field."""


@dataclass(frozen=True)
class Spot:
    """Rectangular spot S_i: centre p_S, heading theta_S (facing away from the road), length, width."""

    id: int
    x: float
    y: float
    heading: float
    length: float
    width: float

    @property
    def pose(self) -> np.ndarray:
        return np.array([self.x, self.y, self.heading])


@dataclass(frozen=True)
class Road:
    """Straight road R_j: centre line C_j from ``start`` to ``end``, swept by a square of side ``width``."""

    id: int
    start: tuple[float, float]
    end: tuple[float, float]
    width: float

    @property
    def heading(self) -> float:
        """theta_R = atan2(y_end - y_start, x_end - x_start)."""
        return math.atan2(self.end[1] - self.start[1], self.end[0] - self.start[0])

    @property
    def length(self) -> float:
        return math.hypot(self.end[0] - self.start[0], self.end[1] - self.start[1])

    def corners(self) -> np.ndarray:
        """The road rectangle: Minkowski sum of C_j and a rotated square of side ``width``."""
        cx = 0.5 * (self.start[0] + self.end[0])
        cy = 0.5 * (self.start[1] + self.end[1])
        return rect_corners(np.array([cx, cy, self.heading]), self.length + self.width, self.width)


@dataclass(frozen=True)
class LotMap:
    """The parking lot L with its spots and roads (everything the ego knows a priori, §II-A)."""

    name: str
    boundary: np.ndarray  # (M, 2) polygon vertices, counter-clockwise
    entrance: np.ndarray  # (2,)
    spots: tuple[Spot, ...]
    roads: tuple[Road, ...]
    source: str = "<memory>"
    _index: dict[int, int] = field(default_factory=dict, repr=False, compare=False)
    #: the validated ``scenario:`` block (avp_world.lot_scenario; empty: the roles come from the geometry)
    scenario: dict = field(default_factory=dict, repr=False, compare=False)
    sha256: str = field(default="", compare=False)  # of the file it was loaded from ("" when not from a file)

    def __post_init__(self) -> None:
        self._index.update({s.id: i for i, s in enumerate(self.spots)})
        object.__setattr__(self, "spot_ids", np.array([s.id for s in self.spots], dtype=np.int64))
        object.__setattr__(self, "spot_poses", np.array([[s.x, s.y, s.heading] for s in self.spots]).reshape(-1, 3))
        object.__setattr__(self, "spot_dims", np.array([[s.length, s.width] for s in self.spots]).reshape(-1, 2))
        object.__setattr__(
            self, "spot_corners", rect_corners(self.spot_poses, self.spot_dims[:, 0], self.spot_dims[:, 1])
        )
        object.__setattr__(
            self, "road_corners", np.array([r.corners() for r in self.roads]).reshape(-1, 4, 2)
        )
        object.__setattr__(
            self, "road_segments", np.array([[r.start, r.end] for r in self.roads], dtype=float).reshape(-1, 2, 2)
        )
        object.__setattr__(self, "road_headings", np.array([r.heading for r in self.roads], dtype=float))

    spot_ids: np.ndarray = field(init=False, repr=False, compare=False)
    spot_poses: np.ndarray = field(init=False, repr=False, compare=False)
    spot_dims: np.ndarray = field(init=False, repr=False, compare=False)
    spot_corners: np.ndarray = field(init=False, repr=False, compare=False)
    road_corners: np.ndarray = field(init=False, repr=False, compare=False)
    road_segments: np.ndarray = field(init=False, repr=False, compare=False)  # (R, 2, 2) centre lines C_j
    road_headings: np.ndarray = field(init=False, repr=False, compare=False)  # (R,) theta_Rj

    @property
    def n_spots(self) -> int:
        return len(self.spots)

    def spot_index(self, spot_id: int) -> int:
        """Row of ``spot_id`` in the spot arrays; KeyError names the unknown id."""
        try:
            return self._index[int(spot_id)]
        except KeyError:
            raise KeyError(f"unknown spot id {spot_id} in lot '{self.name}'") from None

    def has_spot(self, spot_id: int) -> bool:
        return int(spot_id) in self._index

    def boundary_segments(self) -> np.ndarray:
        """(M, 2, 2) edges of the lot polygon."""
        return np.stack([self.boundary, np.roll(self.boundary, -1, axis=0)], axis=1)

    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of the boundary."""
        return (*self.boundary.min(0), *self.boundary.max(0))


# --------------------------------------------------------------------------------------------- load


def _num(value: Any, where: str, *, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise LotMapError(f"{where}: expected a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise LotMapError(f"{where}: must be finite, got {value!r}")
    if positive and v <= 0:
        raise LotMapError(f"{where}: must be > 0, got {value!r}")
    return v


def _point(value: Any, where: str) -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise LotMapError(f"{where}: expected [x, y], got {value!r}")
    return _num(value[0], f"{where}[0]"), _num(value[1], f"{where}[1]")


def _require(d: Any, key: str, where: str) -> Any:
    if not isinstance(d, dict):
        raise LotMapError(f"{where}: expected a mapping, got {type(d).__name__}")
    if key not in d:
        raise LotMapError(f"{where}.{key}: missing")
    return d[key]


#: bounds of a lot map (docs/bad_input.md row 36): the DLP lot has 364 spots in a file of a few kB
MAX_LOT_BYTES = 5_000_000
MAX_SPOTS = 5000
MAX_ROADS = 1000
MAX_BOUNDARY_VERTICES = 10_000


def lot_from_dict(data: Any, source: str = "<memory>") -> LotMap:
    """Build and validate a :class:`LotMap` from parsed YAML. Raises :class:`LotMapError`."""
    src = source
    if not isinstance(data, dict):
        raise LotMapError(f"{src}: top level must be a mapping")
    unknown = set(data) - {"name", "boundary", "entrance", "roads", "spots", "spot_rows", "notes", "scenario"}
    if unknown:
        raise LotMapError(f"{src}: {sorted(unknown)[0]}: unknown key")
    name = str(data.get("name", Path(source).stem))

    raw_boundary = _require(data, "boundary", src)
    if not isinstance(raw_boundary, list) or not 3 <= len(raw_boundary) <= MAX_BOUNDARY_VERTICES:
        raise LotMapError(f"{src}: boundary: expected a list of 3 to {MAX_BOUNDARY_VERTICES} [x, y] vertices")
    boundary = np.array([_point(p, f"{src}: boundary[{i}]") for i, p in enumerate(raw_boundary)])
    entrance = np.array(_point(_require(data, "entrance", src), f"{src}: entrance"))

    roads: list[Road] = []
    raw_roads = _require(data, "roads", src)
    if not isinstance(raw_roads, list) or not 1 <= len(raw_roads) <= MAX_ROADS:
        raise LotMapError(f"{src}: roads: expected a list of 1 to {MAX_ROADS} roads")
    for i, r in enumerate(raw_roads):
        w = f"{src}: roads[{i}]"
        start = _point(_require(r, "start", w), f"{w}.start")
        end = _point(_require(r, "end", w), f"{w}.end")
        width = _num(_require(r, "width", w), f"{w}.width", positive=True)
        if math.hypot(end[0] - start[0], end[1] - start[1]) < 1e-6:
            raise LotMapError(f"{w}: start and end coincide (road of zero length)")
        roads.append(Road(id=int(r.get("id", i)), start=start, end=end, width=width))

    spots: list[Spot] = []
    for i, row in enumerate(data.get("spot_rows", []) or []):
        w = f"{src}: spot_rows[{i}]"
        first = _point(_require(row, "first_center", w), f"{w}.first_center")
        step = _point(_require(row, "step", w), f"{w}.step")
        count = _require(row, "count", w)
        if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= MAX_SPOTS - len(spots):
            raise LotMapError(f"{w}.count: expected an integer in [1, {MAX_SPOTS - len(spots)}] (at most "
                              f"{MAX_SPOTS} spots in a lot), got {count!r}")
        heading = _num(_require(row, "heading", w), f"{w}.heading")
        length = _num(_require(row, "length", w), f"{w}.length", positive=True)
        width = _num(_require(row, "width", w), f"{w}.width", positive=True)
        for k in range(count):
            spots.append(
                Spot(len(spots), first[0] + k * step[0], first[1] + k * step[1], heading, length, width)
            )
    raw_spots = data.get("spots", []) or []
    if not isinstance(raw_spots, list) or len(raw_spots) + len(spots) > MAX_SPOTS:
        raise LotMapError(f"{src}: spots: expected a list; at most {MAX_SPOTS} spots in a lot")
    for i, s in enumerate(raw_spots):
        w = f"{src}: spots[{i}]"
        c = _point(_require(s, "center", w), f"{w}.center")
        sid = s.get("id", len(spots)) if isinstance(s, dict) else None
        if isinstance(sid, bool) or not isinstance(sid, int):
            raise LotMapError(f"{w}.id: expected an integer, got {type(sid).__name__}")
        spots.append(
            Spot(
                sid,
                c[0],
                c[1],
                _num(_require(s, "heading", w), f"{w}.heading"),
                _num(_require(s, "length", w), f"{w}.length", positive=True),
                _num(_require(s, "width", w), f"{w}.width", positive=True),
            )
        )
    if not spots:
        raise LotMapError(f"{src}: spots: the lot has no spots (give 'spots' or 'spot_rows')")
    ids = [s.id for s in spots]
    if len(set(ids)) != len(ids):
        dup = next(i for i in ids if ids.count(i) > 1)
        raise LotMapError(f"{src}: spots: duplicate spot id {dup}")

    lot = LotMap(name=name, boundary=boundary, entrance=entrance, spots=tuple(spots), roads=tuple(roads), source=src)
    _validate_geometry(lot)
    if data.get("scenario") is not None:
        try:
            object.__setattr__(lot, "scenario", parse_scenario_block(data["scenario"], lot, f"{src}: scenario"))
        except ValueError as exc:
            raise LotMapError(str(exc)) from None
    return lot


def _validate_geometry(lot: LotMap) -> None:
    from shapely.geometry import Point, Polygon

    src = lot.source
    poly = Polygon(lot.boundary)
    if not poly.is_valid or poly.area <= 0:
        raise LotMapError(f"{src}: boundary: not a simple polygon with positive area")
    grown = poly.buffer(1e-6)
    if not grown.contains(Point(*lot.entrance)):
        raise LotMapError(f"{src}: entrance: {tuple(lot.entrance)} lies outside the lot boundary")
    for k, s in enumerate(lot.spots):
        if not grown.contains(Polygon(lot.spot_corners[k])):
            raise LotMapError(f"{src}: spots[id={s.id}]: spot lies (partly) outside the lot boundary")
    # pairwise overlap with a small tolerance so that spots sharing an edge are accepted
    c = lot.spot_corners
    n = len(c)
    if n > 1:  # candidate pairs from an R-tree (a lot of 5000 spots has 12.5 M pairs), confirmed exactly
        from shapely import STRtree

        shrunk = rect_corners(lot.spot_poses, lot.spot_dims[:, 0] - 2e-3, lot.spot_dims[:, 1] - 2e-3)
        polys = [Polygon(q) for q in shrunk]
        ii, jj = STRtree(polys).query(polys, predicate="intersects")
        keep = ii < jj
        ii, jj = ii[keep], jj[keep]
        order = np.lexsort((jj, ii))  # the first pair in (i, j) order, as the full pairwise check reported
        ii, jj = ii[order], jj[order]
        bad = rects_overlap(shrunk[ii], shrunk[jj])
        if bad.any():
            k = int(np.argmax(bad))
            raise LotMapError(
                f"{src}: spots[id={lot.spots[ii[k]].id}]: overlaps spot id {lot.spots[jj[k]].id}"
            )


def load_lot(path: str | Path) -> LotMap:
    """Load and validate a lot map YAML file. Raises :class:`LotMapError` naming file and field."""
    from avp_world.safe_yaml import YamlInputError, load_bounded, read_bounded

    p = Path(path)
    if not p.is_file():
        raise LotMapError(f"{p}: no such lot map file")
    try:
        raw = read_bounded(p, MAX_LOT_BYTES)
        data = load_bounded(raw, str(p), MAX_LOT_BYTES)
    except OSError as exc:
        raise LotMapError(f"{p}: cannot read ({exc.strerror})") from None
    except YamlInputError as exc:
        raise LotMapError(str(exc)) from None
    lot = lot_from_dict(data, source=str(p))
    object.__setattr__(lot, "sha256", hashlib.sha256(raw).hexdigest())
    return lot


def bundled_lot_path(name: str = "paper_lot") -> Path:
    """Path of a lot shipped with this package (``maps/<name>.yaml``)."""
    return MAPS_DIR / f"{name}.yaml"


def load_bundled_lot(name: str = "paper_lot") -> LotMap:
    return load_lot(bundled_lot_path(name))

"""Lot maps: the bundled paper lot and one-line validation errors naming file and field."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
import yaml
from shapely.geometry import Polygon

from avp_world.lot import LotMapError, bundled_lot_path, load_lot


def test_paper_lot_layout(paper_lot):
    lot = paper_lot
    assert lot.n_spots == 40
    # four columns of 10 spots: distinct x centres, 10 spots each
    xs, counts = np.unique(np.round(lot.spot_poses[:, 0], 6), return_counts=True)
    assert len(xs) == 4 and set(counts) == {10}
    # 3 vertical + 2 horizontal roads
    vertical = [r for r in lot.roads if abs(math.cos(r.heading)) < 1e-9]
    horizontal = [r for r in lot.roads if abs(math.sin(r.heading)) < 1e-9]
    assert len(vertical) == 3 and len(horizontal) == 2
    # spots inside L, pairwise interiors disjoint, never on a road (shapely oracle)
    boundary = Polygon(lot.boundary)
    polys = [Polygon(c) for c in lot.spot_corners]
    roads = [Polygon(c) for c in lot.road_corners]
    for i, p in enumerate(polys):
        assert boundary.buffer(1e-9).contains(p)
        for q in polys[i + 1:]:
            assert p.intersection(q).area < 1e-9
        for r in roads:
            assert p.intersection(r).area < 1e-9
    # each spot's heading points away from the road it borders: the point 1 m behind the spot's
    # back edge... in front of its road edge lies on a road
    for s in lot.spots:
        road_side = np.array([s.x, s.y]) - (s.length / 2 + 1.0) * np.array([math.cos(s.heading), math.sin(s.heading)])
        from shapely.geometry import Point

        assert any(r.contains(Point(*road_side)) for r in roads), f"spot {s.id} does not face away from a road"


def _paper_dict():
    return yaml.safe_load(bundled_lot_path().read_text())


def _write(tmp_path, data, name="lot.yaml"):
    p = tmp_path / name
    p.write_text(yaml.safe_dump(data) if not isinstance(data, str) else data)
    return p


BAD_CASES = [
    ("spot outside", lambda d: d["spot_rows"][0].__setitem__("first_center", [1.0, 8.375]), "outside"),
    ("overlap", lambda d: d.setdefault("spots", []).append(
        {"id": 99, "center": [9.75, 9.0], "heading": 0.0, "length": 5.5, "width": 2.75}), "overlaps"),
    ("zero road", lambda d: d["roads"][0].__setitem__("end", [3.5, 3.5]), "roads[0]"),
    ("nan", lambda d: d["spot_rows"][1].__setitem__("length", float("nan")), "spot_rows[1].length"),
    ("string number", lambda d: d["roads"][2].__setitem__("width", "wide"), "roads[2].width"),
    ("negative width", lambda d: d["spot_rows"][2].__setitem__("width", -1.0), "spot_rows[2].width"),
    ("missing boundary", lambda d: d.pop("boundary"), "boundary"),
    ("entrance outside", lambda d: d.__setitem__("entrance", [100.0, 0.0]), "entrance"),
    ("unknown key", lambda d: d.__setitem__("spotz", []), "spotz"),
    ("dup id", lambda d: d.setdefault("spots", []).append(
        {"id": 0, "center": [1.0, 1.0], "heading": 0.0, "length": 1.0, "width": 1.0}), "duplicate"),
]


@pytest.mark.parametrize("name,mutate,needle", BAD_CASES, ids=[c[0] for c in BAD_CASES])
def test_bad_maps_give_one_line_naming_file_and_field(tmp_path, name, mutate, needle):
    data = copy.deepcopy(_paper_dict())
    mutate(data)
    path = _write(tmp_path, data)
    with pytest.raises(LotMapError) as exc:
        load_lot(path)
    msg = str(exc.value)
    assert "\n" not in msg
    assert str(path) in msg and needle in msg


def test_not_yaml_and_missing_file(tmp_path):
    with pytest.raises(LotMapError, match="not valid YAML"):
        load_lot(_write(tmp_path, "boundary: [1, 2\n  - : :"))
    with pytest.raises(LotMapError, match="no such lot map file"):
        load_lot(tmp_path / "nope.yaml")


def test_valid_map_roundtrip(tmp_path, paper_lot):
    lot = load_lot(_write(tmp_path, _paper_dict()))
    assert np.array_equal(lot.spot_poses, paper_lot.spot_poses)
    with pytest.raises(KeyError, match="unknown spot id 77"):
        lot.spot_index(77)

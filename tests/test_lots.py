"""Any lot: the scenario roles from a lot's scenario: block or from its geometry, the second
shipped lot end to end in-process, records that name their lot, and one clear error per bad block."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from shapely.geometry import Polygon

from avp_scenario.scenario import ScenarioParams, generate_paper_scenario
from avp_world.geometry import rect_corners
from avp_world.lot import LotMapError, bundled_lot_path, load_bundled_lot, load_lot, lot_from_dict
from avp_world.lot_scenario import derive_lot_scenario, lot_scenario
from avp_world.safe_yaml import load_bounded

PAPER_ROLES = dict(ego_start=(21.5, 38.0, -math.pi / 2), contested=(10, 11, 12, 13, 14, 20, 21, 22, 23, 24),
                   fallback=(tuple(range(0, 10)), tuple(range(30, 40))))


def _paper_dict() -> dict:
    path = bundled_lot_path("paper_lot")
    return load_bounded(path.read_bytes(), str(path), 10**6)


def test_the_paper_lots_geometry_gives_the_paper_protocols_roles():
    """The derivation reproduces the ids the generator hard-coded before lots could say them; the paper lot's
    explicit block says the same."""
    data = _paper_dict()
    data.pop("scenario")
    derived = derive_lot_scenario(lot_from_dict(data))
    assert derived.ego_start == PAPER_ROLES["ego_start"]
    assert derived.contested_spot_ids == PAPER_ROLES["contested"]
    assert derived.fallback_spot_groups == PAPER_ROLES["fallback"]
    assert derived.aisle_width == 7.0
    assert lot_scenario(load_bundled_lot()) == derived


def test_the_side_lot_roles_follow_its_own_geometry():
    lot = load_bundled_lot("side_lot")
    assert lot.scenario == {}  # no block: everything derived
    s = lot_scenario(lot)
    assert s.ego_start == (3.5, 21.5, 0.0)  # west end of the middle road, facing east
    assert s.contested_spot_ids == (13, 14, 15, 16, 17, 22, 23, 24, 25, 26)  # 5 easternmost each side
    assert s.fallback_spot_groups[0][:5] == (8, 7, 6, 5, 4)  # the bottom row, east first


def test_a_lot_block_overrides_the_geometry_key_by_key():
    data = _paper_dict()
    data["scenario"] = {"contested_spot_ids": [15, 16]}
    s = lot_scenario(lot_from_dict(data, "mine.yaml"))
    assert s.contested_spot_ids == (15, 16) and s.ego_start == PAPER_ROLES["ego_start"]
    sc = generate_paper_scenario(lot_from_dict(data, "mine.yaml"), 3, False)
    assert {v.target_spot_id for v in sc.vehicles if not v.parked} <= {15, 16}


@pytest.mark.parametrize("block, field", [
    ({"contested_spot_ids": [10, 99]}, "scenario.contested_spot_ids[1]"),
    ({"contested_spot_ids": [10, 10]}, "scenario.contested_spot_ids[1]"),
    ({"fallback_spot_groups": [[0], "x"]}, "scenario.fallback_spot_groups[1]"),
    ({"ego_start": [1.0, 2.0]}, "scenario.ego_start"),
    ({"aisle_width": -7}, "scenario.aisle_width"),
    ({"entrance_side": "left"}, "scenario.entrance_side"),
    ("nope", "scenario"),
])
def test_a_bad_scenario_block_is_one_error_naming_the_field(block, field):
    data = _paper_dict()
    data["scenario"] = block
    with pytest.raises(LotMapError) as e:
        lot_from_dict(data, "bad_lot.yaml")
    assert str(e.value).startswith(f"bad_lot.yaml: {field}"), str(e.value)


def test_scenarios_on_the_side_lot_keep_the_protocols_properties():
    lot = load_bundled_lot("side_lot")
    roles = lot_scenario(lot)
    boundary = Polygon(lot.boundary)
    for seed in range(15):
        sc = generate_paper_scenario(lot, seed, True, ScenarioParams())
        assert np.allclose(sc.ego_start, roles.ego_start)
        empty = set(lot.spot_ids.tolist()) - {v.id for v in sc.vehicles if v.parked}
        fallbacks = empty - set(roles.contested_spot_ids)
        assert len(fallbacks) == 2 and fallbacks <= set(roles.fallback_spot_groups[0][:5])
        for v in sc.dynamic_vehicles():
            assert v.target_spot_id in roles.contested_spot_ids and v.target_spot_id in empty
            assert boundary.buffer(1e-6).contains(Polygon(rect_corners(v.initial_state, v.length, v.width)))


@pytest.mark.slow
def test_avp_experiment_runs_on_another_lot_and_records_name_it(tmp_path):
    lot_file = bundled_lot_path("side_lot")
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "experiment", "--lot", str(lot_file), "--methods",
                        "bezier", "--scenarios", "2", "--mode", "non-reactive", "--workers", "1", "--no-progress",
                        "--out", str(out)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    recs = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    sha = load_lot(lot_file).sha256
    assert len(recs) == 2 and all(x["lot"] == {"name": "side_lot", "sha256": sha} for x in recs)
    assert all(x["success"] for x in recs), recs
    side_ids = set(load_bundled_lot("side_lot").spot_ids.tolist())
    assert all(x["parked_spot_id"] in side_ids for x in recs)
    assert json.loads((out / "run.json").read_text())["lot"]["sha256"] == sha
    # the same folder refuses another lot
    r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "experiment", "--methods", "bezier", "--scenarios",
                        "2", "--mode", "non-reactive", "--workers", "1", "--no-progress", "--out", str(out)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 2 and "run.json" in r.stderr, r.stderr


def test_a_bad_lot_is_one_error_before_any_episode(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(bundled_lot_path("side_lot").read_text() + "scenario: {contested_spot_ids: [1, 500]}\n")
    r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "experiment", "--lot", str(bad), "--methods",
                        "bezier", "--scenarios", "1", "--no-progress", "--out", str(tmp_path / "o")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2
    assert f"{bad}: scenario.contested_spot_ids[1]: 500 is not a spot id of lot 'side_lot'" in r.stderr, r.stderr


@pytest.mark.slow
def test_the_busy_family_on_the_dlp_lot():
    """The whole DLP lot (364 spots); a busy episode has 20+ moving cars, parking and leaving,
    10+ pedestrians on the lot's roads, spots that free and fill; same seed => same episode; the ego's start is
    clear at t = 0; non-reactive zeroes every passiveness."""
    from avp_sim.core.world import World, WorldConfig
    from avp_traffic.busy import BusyParams, generate_busy_scenario

    lot = load_bundled_lot("dlp_lot")
    assert lot.n_spots == 364 and lot.bounds() == (0.0, 0.0, 140.0, 80.0)
    a = generate_busy_scenario(lot, 3, True, t_final=60.0)
    b = generate_busy_scenario(lot, 3, True, t_final=60.0)
    assert [(v.id, v.target_spot_id) for v in a.vehicles] == [(v.id, v.target_spot_id) for v in b.vehicles]
    assert all(np.array_equal(x.controls, y.controls) for x, y in zip(a.pedestrians, b.pedestrians, strict=True))
    moving = [v for v in a.vehicles if not v.parked]
    parkers = [v for v in moving if v.target_spot_id >= 0]
    from avp_sensing.observation import classify_world

    _, in_spot = classify_world(lot, np.array([rect_corners(v.initial_state, v.length, v.width) for v in moving]))
    leavers = [v for v, s in zip(moving, in_spot, strict=True) if v.target_spot_id < 0 and s >= 0]
    assert len(moving) >= 20 and len(parkers) >= 5 and leavers, (len(moving), len(parkers), len(leavers))
    lo, hi = BusyParams().n_pedestrians
    assert lo <= len(a.pedestrians) <= hi
    assert all(v.passiveness >= 2 for v in moving)
    nr = generate_busy_scenario(lot, 3, False, t_final=60.0)
    assert all(v.passiveness == 0 for v in nr.vehicles) and all(p.passiveness == 0 for p in nr.pedestrians)
    w = World(lot, a, WorldConfig(t_final=60.0))
    assert w.status == "running"  # nothing on the ego's start
    occupied0, _ = w.occupancy()
    walked = 0.0
    for _ in range(599):  # the ego stands at the gate: arrivals queue behind it, cars inside park and leave
        w.step(0.0, 0.0)
        walked = max(walked, float(np.hypot(*(w.ped_pos - np.array([q.initial_position for q in a.pedestrians])).T)
                                   .max()))
        if w.done:
            break
    occupied1, _ = w.occupancy()
    assert (occupied1 & ~occupied0).any() and (occupied0 & ~occupied1).any(), (  # spots filled and freed
        int((occupied1 & ~occupied0).sum()), int((occupied0 & ~occupied1).sum()))
    assert walked > 5.0

"""tools/agent_overlaps.py: which agents overlap, on a hand-built scene (the tool's counts rest on it)."""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from shapely.geometry import Polygon

from avp_world.geometry import rect_corners

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))

from agent_overlaps import overlaps  # noqa: E402

LOT = Polygon([(0, 0), (40, 0), (40, 20), (0, 20)])


def _world(poses, dynamic, braking, peds=()):
    poses = np.asarray(poses, float)
    corners = rect_corners(poses, 4.8, 1.9)
    return SimpleNamespace(
        vehicle_corners=lambda: corners, is_dynamic=np.asarray(dynamic), braking=np.asarray(braking),
        vehicle_ids=np.arange(100, 100 + len(poses)),
        ped_pos=np.asarray([p[:2] for p in peds], float).reshape(-1, 2),
        ped_radii=np.asarray([p[2] for p in peds], float), ped_ids=np.arange(200, 200 + len(peds)))


def test_a_car_driven_into_one_that_brakes_counts_and_is_told_apart_from_two_driving_through():
    # 100 brakes, 101 drives 1 m into its back; 102 and 103 cross, neither braking; 104 grazes 103 (0.1 m²: contact)
    poses = [(10, 5, 0), (11, 5, 0), (30, 10, 0), (30, 10, np.pi / 2), (30.0, 13.3, 0)]
    cars, free, peds = overlaps(_world(poses, [True] * 5, [True, False, False, False, False]), LOT)
    assert cars == {(100, 101), (102, 103)}
    assert free == {(102, 103)}
    assert peds == set()


def test_parked_cars_cars_outside_the_lot_and_a_pedestrian_beside_a_car_do_not_count():
    poses = [(10, 5, 0), (10.5, 5, 0), (-3, 5, 0), (-3.5, 5, 0), (20, 10, 0)]
    peds = [(20.0, 11.3, 0.3), (20.0, 10.0, 0.3)]  # beside car 104 (its side at y = 10.95), and inside it
    cars, _, ped_pairs = overlaps(_world(poses, [False, True, True, True, True], [False] * 5, peds), LOT)
    assert cars == set()  # 100 is parked; 102 and 103 overlap outside the lot (the queue at the gate)
    assert ped_pairs == {(201, 104)}

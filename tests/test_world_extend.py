"""A static world extended from another one's grid (avp_collision.world_extend) is the world a full build gives: every
array equal, on the paper's lot and the DLP lot, with rectangles anywhere (inside obstacles, at the boundary, apart
and overlapping, few or many); and the planner's worlds, built so, are those a full build gives."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from avp_collision.static import StaticWorld
from avp_search.settings import CollisionSettings
from avp_world.lot import load_lot

MAPS = Path(__file__).resolve().parents[1] / "src/avp_world/avp_world/maps"


@pytest.mark.parametrize("lot_file", ["paper_lot.yaml", "dlp_lot.yaml"])
@pytest.mark.parametrize("seed", range(6))
def test_an_extended_world_equals_a_full_build(lot_file, seed, monkeypatch):
    lot = load_lot(MAPS / lot_file)
    rng = np.random.default_rng(seed)
    occ = rng.choice(lot.n_spots, size=lot.n_spots // 3, replace=False)
    poses, dims = lot.spot_poses[occ], lot.spot_dims[occ]
    xmin, ymin, xmax, ymax = lot.bounds()
    n = int(rng.integers(1, 6)) if seed < 4 else 40  # 40: one transform over them all
    extra_poses = np.column_stack([rng.uniform(xmin - 2, xmax + 2, n), rng.uniform(ymin - 2, ymax + 2, n),
                                   rng.uniform(-np.pi, np.pi, n)])
    extra_dims = np.column_stack([rng.uniform(0.5, 5.5, n), rng.uniform(0.5, 2.5, n)])
    if seed == 0:  # two overlapping and one inside a spot
        extra_poses[:2, :2] = lot.spot_poses[occ[0], :2]
        extra_poses[1, :2] += 0.3
    cfg = CollisionSettings()
    base = StaticWorld(lot, poses, dims, 4.8, 1.9, cfg)
    i, j = np.argwhere(base.edt > 2.0)[rng.integers(len(np.argwhere(base.edt > 2.0)))]
    extra_poses[-1, :2] = base.origin + (np.array([j, i]) + 0.5) * base.res  # one in open road
    all_p, all_d = np.concatenate([poses, extra_poses]), np.concatenate([dims, extra_dims])
    full = StaticWorld(lot, all_p, all_d, 4.8, 1.9, cfg)
    monkeypatch.setattr(StaticWorld, "_build_grid", lambda self: pytest.fail("built in full"))
    ext = StaticWorld(lot, all_p, all_d, 4.8, 1.9, cfg, base=base)
    assert np.array_equal(ext.rect_poses, full.rect_poses)
    for name in ("grid", "edt", "depth", "_sdf_flat"):
        assert np.array_equal(getattr(ext, name), getattr(full, name)), name
    assert ext.grid.sum() > base.grid.sum() and (ext.edt < base.edt).any()


def test_a_world_that_does_not_extend_its_base_is_built_in_full():
    lot = load_lot(MAPS / "paper_lot.yaml")
    cfg = CollisionSettings()
    base = StaticWorld(lot, lot.spot_poses[:3], lot.spot_dims[:3], 4.8, 1.9, cfg)
    other = StaticWorld(lot, lot.spot_poses[3:6], lot.spot_dims[3:6], 4.8, 1.9, cfg, base=base)
    full = StaticWorld(lot, lot.spot_poses[3:6], lot.spot_dims[3:6], 4.8, 1.9, cfg)
    assert np.array_equal(other.grid, full.grid) and np.array_equal(other._sdf_flat, full._sdf_flat)


def test_the_planners_worlds_are_full_builds(monkeypatch):
    """The planner builds its worlds by extension (the spots' world, then the vehicles); each equals a full build."""
    from avp_planner.core.decision import EgoPlanner
    from avp_world.types import Observation, ObservedVehicle

    lot = load_lot(MAPS / "dlp_lot.yaml")
    planner = EgoPlanner(lot)
    b = np.zeros(lot.n_spots)
    b[::2] = 1.0
    rng = np.random.default_rng(3)
    rows = rng.choice(np.nonzero(b)[0], 12, replace=False)
    vehicles = tuple(ObservedVehicle(id=i + 1, length=4.9, width=2.1, is_static=True,
                                     history=(lot.spot_poses[k] + [0.3, -0.2, 0.05])[None])
                     for i, k in enumerate(rows))
    obs = Observation(step=0, dt=0.1, ego_pose=np.r_[lot.entrance, 0.0], ego_length=4.8, ego_width=1.9,
                      ego_speed=0.0, vacant_spot_ids=np.zeros(0, np.int64), occupied_spot_ids=np.zeros(0, np.int64),
                      vehicles=vehicles)
    full_builds = []
    build = StaticWorld._build_grid
    monkeypatch.setattr(StaticWorld, "_build_grid", lambda self: full_builds.append(1) or build(self))
    world = planner._static_world(obs, b)
    assert len(full_builds) == 1  # the spots' world; the vehicles were added to it
    monkeypatch.undo()
    (spots,) = planner._spots_cache.values()  # built from this one
    assert len(world.rect_poses) == len(spots.rect_poses) + 12
    full = StaticWorld(lot, world.obstacle_poses, world.obstacle_dims, 4.8, 1.9, planner.settings.collision)
    for name in ("grid", "edt", "depth", "_sdf_flat"):
        assert np.array_equal(getattr(world, name), getattr(full, name)), name

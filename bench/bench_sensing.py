#!/usr/bin/env python3
"""Benchmark of one ray cast of the occlusion-aware observation model (paper §III-A).

Scene: the paper lot (40 spots) with a car parked in every spot (4.6 x 1.85 m at the spot centre with
the spot heading) plus 2 dynamic cars on the middle road; the ego drives down the middle road
(x = 21.5, y uniform in [5, 38], heading -pi/2) with the default sensor (disc of radius 11.5 m,
360 rays). Prints median / p95 / mean of ``RayCaster.cast`` in ms and the machine.

Usage: python bench/bench_sensing.py [--repeats 2000] [--n-ray 360] [--seed 0]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from avp_sensing.observation import RayCaster, SensorConfig
from avp_world.geometry import rect_corners
from avp_world.lot import load_bundled_lot


def build_scene() -> tuple[object, np.ndarray, np.ndarray, np.ndarray]:
    lot = load_bundled_lot("paper_lot")
    parked = rect_corners(lot.spot_poses, 4.6, 1.85)
    dynamic = rect_corners(np.array([[21.5, 12.0, np.pi / 2], [21.5, 30.0, -np.pi / 2]]), 4.6, 1.85)
    vehicles = np.concatenate([parked, dynamic])
    peds = np.array([[18.5, 20.0], [24.5, 26.0], [21.0, 35.0]])
    radii = np.full(len(peds), 0.4)
    return lot, vehicles, peds, radii


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=2000, help="timed casts (default 2000)")
    ap.add_argument("--n-ray", type=int, default=360, help="rays per cast (default 360)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    lot, vehicles, peds, radii = build_scene()
    caster = RayCaster(lot, SensorConfig(n_ray=args.n_ray))
    rng = np.random.default_rng(args.seed)
    poses = np.column_stack(
        [np.full(args.repeats, 21.5), rng.uniform(5.0, 38.0, args.repeats), np.full(args.repeats, -np.pi / 2)]
    )
    for pose in poses[: min(200, args.repeats)]:  # warm-up
        caster.cast(pose, vehicles, peds, radii)

    times = np.empty(args.repeats)
    seen = 0
    for i, pose in enumerate(poses):
        t0 = time.perf_counter()
        scan = caster.cast(pose, vehicles, peds, radii)
        times[i] = time.perf_counter() - t0
        seen += int(scan.seen_vehicles.sum())
    ms = times * 1e3

    print(
        f"scene: lot '{lot.name}' ({lot.n_spots} spots), N = {len(vehicles)} vehicles "
        f"({lot.n_spots} parked + {len(vehicles) - lot.n_spots} dynamic), P = {len(peds)} pedestrians"
    )
    print(
        f"sensor: disc r = {caster.config.radius} m, n_ray = {caster.n_ray}; "
        f"ego on the middle road x = 21.5, y ~ U[5, 38], heading -pi/2; mean vehicles seen "
        f"{seen / args.repeats:.1f}"
    )
    print(
        f"cast x {args.repeats}: median {np.median(ms):.3f} ms, p95 {np.percentile(ms, 95):.3f} ms, "
        f"mean {ms.mean():.3f} ms, min {ms.min():.3f} ms"
    )
    # the whole observation step of the simulator (ray casting + spot/vehicle classification + histories)
    from avp_scenario.scenario import generate_paper_scenario
    from avp_sim.core.world import World, WorldConfig

    world = World(lot, generate_paper_scenario(lot, args.seed, True), WorldConfig(sensor=caster.config))
    obs_times = []
    for _ in range(300):
        t0 = time.perf_counter()
        world.observe()
        obs_times.append(time.perf_counter() - t0)
        world.step(1.0, 0.0)
        if world.done:
            break
    om = np.array(obs_times[20:]) * 1e3
    print(
        f"World.observe() (seeded scenario, {len(world.states)} vehicles) x {len(om)}: median {np.median(om):.3f} ms, "
        f"p95 {np.percentile(om, 95):.3f} ms"
    )
    print(
        f"machine: {platform.platform()}, {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} CPUs, Python {platform.python_version()}, numpy {np.__version__}"
    )


if __name__ == "__main__":
    main()

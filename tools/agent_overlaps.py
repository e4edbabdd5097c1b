"""Do the simulator's agents drive through each other? (noticed in the busy lot's gridlocks.)

§III-B's reactive agents brake for the ego only; nothing makes a car stop for another car or for a pedestrian. On
the paper's lot, with one or two moving cars, they seldom meet. On the busy lot a car that stops for the ego is
driven into by the cars behind it. This tool measures how often, with shapely as the judge of overlap (not the
simulator's own geometry):

    python tools/agent_overlaps.py OUT.jsonl SEEDS [--method bezier] [--lot busy|paper] [--t-final 60]
                                   [--sim-param agents_yield=true]

For each seed it runs the method's episode (reactive mode, the shipped parameters, as tools/run_seeds.py) and counts,
over the steps:

* ``vehicle_steps``: steps in which two moving cars, both wholly inside the lot, overlap by more than 0.5 m²
  (``vehicle_pairs`` distinct pairs; ``vehicle_steps_neither_braking``: of those steps, the ones where some
  overlapping pair has neither car braking for the ego);
* ``pedestrian_steps``: steps in which a pedestrian's disc overlaps a moving car by more than 0.05 m²
  (``pedestrian_pairs`` distinct pairs).

Cars queueing outside the lot (they wait outside the gate, where no ray reaches) are left out. One JSON line per
seed is printed and appended to OUT.jsonl.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

VEHICLE_AREA, PEDESTRIAN_AREA = 0.5, 0.05  # m²: overlaps smaller than these are contact, not driving through


def overlaps(world, lot_poly) -> tuple[set, set, set]:
    """(overlapping moving-car pairs, of them the pairs with neither car braking, pedestrian-car pairs) now."""
    from shapely.geometry import Point, Polygon
    from shapely.strtree import STRtree

    corners = world.vehicle_corners()
    idx = [i for i in range(len(corners)) if world.is_dynamic[i] and lot_poly.contains(Polygon(corners[i]))]
    polys = [Polygon(corners[i]) for i in idx]
    cars, free, peds = set(), set(), set()
    if polys:
        tree = STRtree(polys)
        for a, b in zip(*tree.query(polys, predicate="intersects"), strict=True):
            if a < b and polys[a].intersection(polys[b]).area > VEHICLE_AREA:
                pair = (int(world.vehicle_ids[idx[a]]), int(world.vehicle_ids[idx[b]]))
                cars.add(pair)
                if not (world.braking[idx[a]] or world.braking[idx[b]]):
                    free.add(pair)
        for k, (pos, r) in enumerate(zip(world.ped_pos, world.ped_radii, strict=True)):
            disc = Point(float(pos[0]), float(pos[1])).buffer(float(r))
            for j in tree.query(disc, predicate="intersects"):
                if polys[j].intersection(disc).area > PEDESTRIAN_AREA:
                    peds.add((int(world.ped_ids[k]), int(world.vehicle_ids[idx[j]])))
    return cars, free, peds


def main(argv: list[str]) -> int:
    from probe_episodes import emit, episodes
    from shapely.geometry import Polygon

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("seeds")
    ap.add_argument("--method", default="bezier")
    ap.add_argument("--lot", choices=["busy", "paper"], default="busy")
    ap.add_argument("--t-final", type=float, default=60.0)
    ap.add_argument("--sim-param", action="append", default=[], metavar="KEY=VALUE",
                    help="an avp_sim parameter (repeatable), e.g. agents_yield=true")
    a = ap.parse_args(argv)
    for seed, world, ego in episodes(a.method, a.seeds, a.t_final, a.sim_param, lot=a.lot):
        lot_poly = Polygon(world.lot.boundary)
        v_steps = v_free = p_steps = 0
        v_pairs: set = set()
        p_pairs: set = set()
        while not world.done:
            world.step(*ego.step(world.observe()).command)
            cars, free, peds = overlaps(world, lot_poly)
            v_steps += bool(cars)
            v_free += bool(free)
            p_steps += bool(peds)
            v_pairs |= cars
            p_pairs |= peds
        emit(a.out, {"method": a.method, "lot": a.lot, "sim_params": a.sim_param, "seed": seed,
                     "status": world.status, "steps": world.step_index, "vehicle_steps": v_steps,
                     "vehicle_steps_neither_braking": v_free, "vehicle_pairs": len(v_pairs),
                     "pedestrian_steps": p_steps, "pedestrian_pairs": len(p_pairs)})
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

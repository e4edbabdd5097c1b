#!/usr/bin/env python3
"""How fast the simulator answers hostile and large ``reset_episode`` requests (docs/bad_input.md rows 30-32 and 50).

Starts the simulator (lock-step, paper lot, as a real process over DDS) and calls its ``reset_episode`` service
from this process with every request of bench/hostile_requests.py, ``--repeats`` times each, then with the largest
requests it accepts: the bundled two_cars.yaml by name, the same text padded with comments to just under the
1 MB cap, and a scenario with every spot of the lot vacant and as many dynamic vehicles as validate. Prints a
markdown table of the round-trip times (median and worst, ms) and whether each was refused with the expected
reason; also times the core alone (``requested_scenario`` + ``make_world``, no DDS).

Usage: python bench/bench_requests.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from hostile_requests import SCENARIO, hostile_requests  # noqa: E402


def accepted_requests(lot) -> dict[str, dict]:
    """The largest requests the simulator takes: a bundled file, a padded text, a scenario as full as validates."""
    from avp_scenario.scenario import ALL_MANEUVERS, ScenarioError
    from avp_sim.core.scenario_file import scenario_from_dict

    text = SCENARIO.read_text()
    base = yaml.safe_load(text)
    full = {**base, "vacant_spot_ids": [int(s) for s in lot.spot_ids], "dynamic_vehicles": []}
    for sid in lot.spot_ids:  # greedily: every vacant spot a dynamic vehicle that still validates
        for m in ALL_MANEUVERS:
            trial = {**full, "dynamic_vehicles": [*full["dynamic_vehicles"], {"target_spot": int(sid),
                                                                               "maneuver": "/".join(m)}]}
            try:
                scenario_from_dict(lot, trial, "x", 0, True)
            except ScenarioError:
                continue
            full = trial
            break
    pad = "#" * (999_000 - len(text)) + "\n"
    return {"two_cars.yaml by name": {"scenario_file": "two_cars.yaml"},
            f"{len(full['dynamic_vehicles'])} vehicles, {len(full['vacant_spot_ids'])} vacant": {
                "scenario_yaml": yaml.safe_dump(full)},
            "two_cars + comments (999 KB)": {"scenario_yaml": text + pad}}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()

    import os
    import random

    os.environ["ROS_DOMAIN_ID"] = os.environ.get("ROS_DOMAIN_ID") or str(random.randint(110, 200))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    import rclpy

    from avp_bringup.graph import Graph, NodeSpec
    from avp_common.services import call_idempotent
    from avp_msgs.srv import ResetEpisode
    from avp_sim.core.factory import make_world
    from avp_sim.core.scenario_source import requested_scenario
    from avp_sim.params import SIM_PARAMS
    from avp_world.lot import load_lot

    lot = load_lot(Path(__file__).resolve().parents[1] / "src/avp_world/avp_world/maps/paper_lot.yaml")
    hostile, accepted = hostile_requests(), accepted_requests(lot)
    # the core alone: parse + validate + build, no DDS
    p = {s.name: s.default for s in SIM_PARAMS}
    dirs = [SCENARIO.parent]
    core: dict[str, float] = {}
    for name, fields in [*((n, f) for n, (f, _) in hostile.items()), *accepted.items()]:
        t0 = time.perf_counter()
        try:
            make_world(lot, p, 3, True, scenario_data=requested_scenario(fields.get("scenario_file", ""),
                                                                         fields.get("scenario_yaml", ""), dirs))
        except Exception:  # noqa: BLE001 - refused: that is what is measured
            pass
        core[name] = (time.perf_counter() - t0) * 1e3

    rclpy.init()
    node = rclpy.create_node("bench_requests", namespace="/avp")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        spec = NodeSpec("avp_sim", "avp_sim", "sim_node", "config/sim.param.yaml",
                        {"seed": 3, "publish_markers": False})
        with Graph([spec], Path(tmp), env=dict(os.environ)):
            client = node.create_client(ResetEpisode, "reset_episode")
            if not client.wait_for_service(timeout_sec=60):
                print("no reset_episode service", file=sys.stderr)
                return 1
            call = lambda req: call_idempotent(client, req, lambda s: rclpy.spin_once(node, timeout_sec=s),  # noqa: E731
                                               timeout=60)
            call(ResetEpisode.Request(seed=3, reactive=True))  # warm-up
            for kind, items in (("refused", {n: f for n, (f, _) in hostile.items()}), ("accepted", accepted)):
                for name, fields in items.items():
                    times, ok = [], True
                    for _ in range(args.repeats):
                        req = ResetEpisode.Request(seed=3, reactive=True, **fields)
                        t0 = time.perf_counter()
                        r = call(req)
                        times.append((time.perf_counter() - t0) * 1e3)
                        want = hostile[name][1] if kind == "refused" else None
                        ok = ok and (r.success if want is None else (not r.success and want in r.message))
                    size = len(fields.get("scenario_yaml", "").encode()) or len(fields.get("scenario_file", ""))
                    rows.append((kind, name, size, statistics.median(times), max(times), core[name], ok))
    node.destroy_node()
    rclpy.try_shutdown()
    print("| request | kind | bytes | round trip median / worst [ms] | core alone [ms] | as expected |\n"
          "|---|---|--:|--:|--:|---|")
    for kind, name, size, med, worst, c, ok in rows:
        print(f"| {name} | {kind} | {size} | {med:.1f} / {worst:.1f} | {c:.1f} | {'yes' if ok else 'NO'} |")
    worst_refused = max(r[4] for r in rows if r[0] == "refused")
    worst_accepted = max(r[4] for r in rows if r[0] == "accepted")
    print(f"\nworst refused {worst_refused:.1f} ms, worst accepted {worst_accepted:.1f} ms ({args.repeats} repeats)")
    return 0 if all(r[6] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())

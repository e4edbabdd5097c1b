"""K egos over DDS against the in-process fleet, seed by seed (docs/world.md, "Several egos").

    python tools/check_fleet_dds.py [--egos 2] [--seeds 0-19] [--method bezier] [--t-final 60] [--out DIR]

One live graph (`avp launch --egos K` in lock-step, wall-clock caps lifted, on a ROS domain of its own) runs every
seed, each episode started with the simulator's ``reset_episode``; the in-process fleet
(:func:`avp_episode.fleet.run_fleet_inproc`) runs the same seed. Each ego's poses, step by step from its entry,
must be equal bit for bit. Prints one line per seed and the count; exit status 1 if any differs.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--egos", type=int, default=2)
    ap.add_argument("--seeds", default="0-19")
    ap.add_argument("--method", default="bezier")
    ap.add_argument("--t-final", type=float, default=60.0)
    ap.add_argument("--out", type=Path, default=Path("out/check_fleet_dds"))
    args = ap.parse_args(argv)
    a, _, b = args.seeds.partition("-")
    seeds = list(range(int(a), int(b) + 1)) if b else [int(a)]

    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from avp_bringup.domain import _try_lock
    from avp_bringup.graph import Graph, fleet_graph
    from avp_common.services import call_once
    from avp_episode.fleet import run_fleet_inproc
    from avp_episode.run_config import RunConfig, run_profile, sim_values
    from avp_monitor.monitor import EpisodeMonitor
    from avp_msgs.srv import ResetEpisode
    from avp_sim.core.factory import load_lot_param

    cfg = RunConfig(t_final=args.t_final)
    sim_p = sim_values(cfg)
    lot = load_lot_param(sim_p["lot_file"])
    profiles = [run_profile(args.method, cfg)] * args.egos
    domain = next(d for d in range(120, 230) if _try_lock(d))
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    nodes = fleet_graph(profiles, deterministic=True, sim_extra={
        "t_final": args.t_final, "autostart": False, "publish_markers": False, "min_debug_subscribers": 1,
        "egos.entry_interval": sim_p["egos.entry_interval"]})
    rclpy.init()
    monitor = EpisodeMonitor()
    ex = SingleThreadedExecutor()
    ex.add_node(monitor)
    client = monitor.create_client(ResetEpisode, "reset_episode")
    args.out.mkdir(parents=True, exist_ok=True)
    graph = Graph(nodes, args.out / "logs")
    graph.start()
    rows, equal = [], 0
    try:
        t0 = time.monotonic()
        while not (client.service_is_ready() and all(
                monitor.count_subscribers(f"/avp/ego{i}/observation") >= 3
                and monitor.count_publishers(f"/avp/ego{i}/cmd") >= 1 for i in range(args.egos))):
            ex.spin_once(timeout_sec=0.1)
            if time.monotonic() - t0 > 120:
                raise RuntimeError(f"graph not up after 120 s; logs in {args.out / 'logs'}")
        t1 = time.monotonic()
        while time.monotonic() - t1 < 1.0:
            ex.spin_once(timeout_sec=0.05)
        for seed in seeds:
            keep: dict = {}
            run_fleet_inproc(lot, sim_p, profiles, seed, True, cfg, keep=keep)
            world = keep["world"]
            log_egos = np.asarray(world.log_egos)
            expected = [log_egos[int(world.egos.entered_step[i]):, i] for i in range(args.egos)
                        if world.egos.entered_step[i] >= 0]
            monitor.gt.clear()
            monitor.status = None
            w0 = time.monotonic()
            call_once(client, ResetEpisode.Request(seed=seed, reactive=True), lambda s: ex.spin_once(timeout_sec=s),
                      lambda s=seed: monitor.status is not None and monitor.status.seed == s, timeout=30.0)
            while not (monitor.finished and monitor.status.seed == seed) and time.monotonic() - w0 < 900:
                ex.spin_once(timeout_sec=0.1)
            t2 = time.monotonic()
            while len(monitor.gt) < monitor.status.step + 1 and time.monotonic() - t2 < 30:
                ex.spin_once(timeout_sec=0.05)
            got = [monitor.ego_trajectory(i) for i in range(len(expected))]
            same = all(g.shape == e.shape and np.array_equal(g, e) for g, e in zip(got, expected, strict=True))
            equal += same
            row = {"seed": seed, "equal": same, "steps": int(monitor.status.step), "egos_entered": len(expected),
                   "states": [str(s) for s in world.egos.status], "wall_s": round(time.monotonic() - w0, 1)}
            rows.append(row)
            print(json.dumps(row), flush=True)
    finally:
        graph.stop()
        monitor.destroy_node()
        rclpy.try_shutdown()
    (args.out / "check.json").write_text(json.dumps({"egos": args.egos, "method": args.method, "rows": rows}) + "\n")
    print(f"{equal} of {len(rows)} seeds equal (K = {args.egos}, {args.method}, t_f {args.t_final} s)")
    return 0 if equal == len(rows) == len(seeds) else 1


if __name__ == "__main__":
    sys.exit(main())

"""Soak: many consecutive episodes through the live graph without restarting a node; resident memory per node.

Starts the default graph (simulator, perception nodes, planner — `avp_bringup.graph.default_graph`) in
lock-step, then runs ``--episodes`` episodes one after the other through the simulator's ``reset_episode``
service (seeds ``--seed0``, ``--seed0`` + 1, ... — a seed the §VI-A generator cannot build is skipped —
reactive and non-reactive alternating, ``--t-final`` seconds of sim time each, or until the episode ends
earlier). Prints every node's resident set size (VmRSS from /proc) at
launch, after the first episode (warm: models loaded, caches built) and at the end, and the growth from
the first episode to the last. Every node must still be running at the end.

Usage: python bench/bench_soak.py [--episodes 200] [--t-final 10] [--out out/soak.json]
"""

from __future__ import annotations

import argparse
import json
import os
import random
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TERMINAL = (2, 3, 4)  # EpisodeStatus success, collision, timeout


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--t-final", type=float, default=10.0, help="sim seconds per episode")
    ap.add_argument("--seed0", type=int, default=0)
    ap.add_argument("--ego", choices=("planner", "scripted"), default="planner")
    ap.add_argument("--episode-timeout", type=float, default=120.0, help="wall seconds per episode")
    ap.add_argument("--out", default=str(ROOT / "out" / "soak.json"))
    args = ap.parse_args(argv)

    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(120, 200)))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    import rclpy

    from avp_bringup.graph import Graph, NodeSpec, default_graph
    from avp_common.qos import STATUS
    from avp_msgs.msg import EpisodeStatus, Observation
    from avp_msgs.srv import ResetEpisode

    nodes = default_graph(args.ego)
    sim = nodes[0]
    n_obs = sim.extra_params.get("min_subscribers", len(nodes) - 1)
    nodes[0] = NodeSpec(sim.name, sim.package, sim.executable, sim.param_file,
                        {**sim.extra_params, "autostart": False, "t_final": args.t_final, "publish_markers": False,
                         "min_subscribers": n_obs})
    log_dir = ROOT / "out" / "logs" / time.strftime("soak-%Y%m%d-%H%M%S")
    rclpy.init()
    node = rclpy.create_node("avp_soak", namespace="/avp")
    status: list[EpisodeStatus] = []
    node.create_subscription(EpisodeStatus, "episode_status", status.append, STATUS)
    node.create_subscription(Observation, "observation", lambda m: None, 10)
    client = node.create_client(ResetEpisode, "reset_episode")
    graph = Graph(nodes, log_dir)
    graph.start()
    pids = {name: p.pid for name, p in graph.procs.items()}
    rss = {"launch": {}, "first": {}, "end": {}}
    results, skipped = [], []
    t_start = time.monotonic()
    try:
        if not client.wait_for_service(timeout_sec=60):
            print("[soak] no reset_episode service", file=sys.stderr)
            return 1
        time.sleep(2.0)
        rss["launch"] = {n: rss_mb(p) for n, p in pids.items()}
        seed = args.seed0 - 1
        for i in range(args.episodes):
            reactive = i % 2 == 0
            while True:
                seed += 1
                fut = client.call_async(ResetEpisode.Request(seed=seed, reactive=reactive))
                t0 = time.monotonic()
                while not fut.done() and time.monotonic() - t0 < 30:
                    rclpy.spin_once(node, timeout_sec=0.05)
                if not fut.done():
                    print(f"[soak] reset {seed}: no answer", file=sys.stderr)
                    return 1
                if fut.result().success:
                    break
                skipped.append(seed)  # e.g. "no collision-free plans": the generator's limit, not the graph's
                print(f"[soak] skipping seed {seed}: {fut.result().message}", flush=True)

            def done(seed=seed) -> bool:
                return bool(status) and status[-1].seed == seed and status[-1].state in TERMINAL

            while not done() and time.monotonic() - t0 < args.episode_timeout:
                rclpy.spin_once(node, timeout_sec=0.05)
                dead = {n: rc for n, rc in graph.poll().items() if rc is not None}
                if dead:
                    print(f"[soak] node(s) died in episode {i}: {dead}; logs in {log_dir}", file=sys.stderr)
                    return 1
            if not done():
                print(f"[soak] episode {i} (seed {seed}) did not end within {args.episode_timeout} s; logs in "
                      f"{log_dir}", file=sys.stderr)
                return 1
            s = status[-1]
            results.append({"seed": seed, "reactive": reactive, "state": int(s.state), "steps": int(s.step)})
            if i == 0:
                rss["first"] = {n: rss_mb(p) for n, p in pids.items()}
            if (i + 1) % 20 == 0:
                print(f"[soak] {i + 1} episodes, {time.monotonic() - t_start:.0f} s; RSS MB "
                      + ", ".join(f"{n} {rss_mb(p):.1f}" for n, p in pids.items()), flush=True)
        rss["end"] = {n: rss_mb(p) for n, p in pids.items()}
        alive = all(rc is None for rc in graph.poll().values())
    finally:
        graph.stop()
        node.destroy_node()
        rclpy.try_shutdown()
    wall = time.monotonic() - t_start
    growth = {n: rss["end"][n] - rss["first"][n] for n in pids}
    print(f"\n{len(results)} episodes ({args.t_final} s sim each, lock-step) in {wall:.0f} s wall, no node "
          f"restarted; all alive at the end: {alive}")
    print(f"| node | RSS at launch [MB] | after episode 1 [MB] | after episode {len(results)} [MB] | growth [MB] |")
    print("|---|---|---|---|---|")
    for n in pids:
        print(f"| {n} | {rss['launch'][n]:.1f} | {rss['first'][n]:.1f} | {rss['end'][n]:.1f} | {growth[n]:+.1f} |")
    states = {k: sum(r["state"] == v for r in results) for k, v in (("success", 2), ("collision", 3), ("timeout", 4))}
    print(f"seeds {args.seed0}..{seed} (skipped, not generable: {skipped})")
    print(f"episode ends: {states}; largest growth {max(growth.values()):+.1f} MB (limit 50 MB)")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"episodes": results, "rss_mb": rss, "growth_mb": growth, "wall_s": wall,
                               "t_final": args.t_final, "alive": alive, "skipped_seeds": skipped}, indent=1) + "\n")
    return 0 if alive and max(growth.values()) < 50.0 else 1


if __name__ == "__main__":
    sys.exit(main())

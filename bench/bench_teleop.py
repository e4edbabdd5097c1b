#!/usr/bin/env python3
"""Latency from a person's command to the simulator applying it (docs/teleop.md): a real-time simulator with one
driven car (a process of its own, on a ROS domain of its own), and this process publishing ``--commands`` Twists on
``/avp/driver0/cmd_vel`` at ``--rate`` Hz, each with a speed no other command has (small, alternating in sign, so
the car stays where it is). For every command the step that applied it is found in ``debug/ground_truth`` (the
car's displacement over that step, read back through eq. (1), is that speed). Two latencies: **applied** — from the
publication to the DDS source timestamp of that step's ground truth, which the simulator publishes right after the
step that applied the command (the same machine's clock) — and **seen** — to this process receiving it, which adds
the ground truth's own trip. Commands a
newer one replaced before a step came are counted apart (never applied, as intended). Target: p95 at most one step
(dt = 100 ms).

Usage: python bench/bench_teleop.py [--commands 1000] [--rate 7.3] [--json out/bench_teleop.json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--commands", type=int, default=1000)
    ap.add_argument("--rate", type=float, default=7.3, help="commands a second; not a divisor of 10 Hz, so that "
                    "they come at every phase of the simulator's step [7.3]")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)

    import rclpy
    from geometry_msgs.msg import Twist
    from rclpy.serialization import deserialize_message

    from avp_bringup.domain import _try_lock
    from avp_bringup.graph import Graph, NodeSpec
    from avp_common.drain import draining_subscription
    from avp_common.qos import GROUND_TRUTH
    from avp_msgs.msg import AgentState, GroundTruth

    domain = next(d for d in range(150, 230) if _try_lock(d))
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    spec = NodeSpec("avp_sim", "avp_sim", "sim_node", "config/sim.param.yaml", {
        "mode": "realtime", "realtime_wait_first_command": False, "drivers.count": 1,
        "drivers.poses": "21.5,3.5,1.5707963267948966", "seed": 3, "t_final": 3600.0, "publish_markers": False})
    graph = Graph([spec], Path("out/bench_teleop/logs"))
    rclpy.init()
    node = rclpy.create_node("bench_teleop", namespace="/avp")
    pub = node.create_publisher(Twist, "driver0/cmd_vel", 10)
    poses: dict[int, tuple[np.ndarray, int, int]] = {}  # step -> (pose, source ns, reception ns), system clock

    def on_gt(raw, info) -> None:
        m = deserialize_message(raw, GroundTruth)
        for a in m.agents:
            if a.kind == AgentState.KIND_DRIVEN and a.id == 0:
                poses[int(m.step)] = (np.array([a.pose.x, a.pose.y, a.pose.theta]), int(info["source_timestamp"]),
                                      time.time_ns())

    draining_subscription(node, GroundTruth, "/avp/debug/ground_truth", on_gt, GROUND_TRUTH, with_info=True)
    graph.start()
    sent: dict[float, int] = {}  # speed -> publication ns
    try:
        t0 = time.monotonic()
        while len(poses) < 10 and time.monotonic() - t0 < 60:
            rclpy.spin_once(node, timeout_sec=0.1)
        period = 1.0 / args.rate
        nxt = time.monotonic()
        for i in range(args.commands):
            v = round((0.01 + 0.0001 * (i % 100)) * (1 if i % 2 == 0 else -1), 6)
            while time.monotonic() < nxt:
                rclpy.spin_once(node, timeout_sec=max(0.0, nxt - time.monotonic()))
            t = Twist()
            t.linear.x = v
            sent[v] = time.time_ns()  # a value repeats every 100 commands: keep the latest publication
            pub.publish(t)
            nxt += period
            _match(poses, sent)
        t1 = time.monotonic()
        while time.monotonic() - t1 < 2.0:
            rclpy.spin_once(node, timeout_sec=0.05)
        _match(poses, sent)
    finally:
        graph.stop()
        node.destroy_node()
        rclpy.try_shutdown()
    applied, seen = np.array(_LAT) / 1e6, np.array(_SEEN) / 1e6
    report = {"commands": args.commands, "rate_hz": args.rate, "applied": len(applied),
              "applied_ms": _stats(applied), "seen_ms": _stats(seen),
              "load_end": [round(x, 2) for x in os.getloadavg()], "cpus": os.cpu_count()}
    print(json.dumps(report))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=1) + "\n")
    return 0


_LAT: list[int] = []  # publication -> the applying step's ground truth sent [ns]
_SEEN: list[int] = []  # publication -> received here [ns]
_DONE: set[int] = set()


def _stats(x: np.ndarray) -> dict:
    return {"median": round(float(np.median(x)), 1), "p95": round(float(np.percentile(x, 95)), 1),
            "max": round(float(x.max()), 1)}


def _match(poses: dict, sent: dict) -> None:
    """Each new step's speed (eq. 1 read back) -> the command with that speed -> its latency."""
    for k in sorted(poses):
        if k in _DONE or k - 1 not in poses:
            continue
        _DONE.add(k)
        (a, _, _), (b, t_src, t_rx) = poses[k - 1], poses[k]
        v = round(float((b[0] - a[0]) * math.cos(a[2]) + (b[1] - a[1]) * math.sin(a[2])) / 0.1, 6)
        if v in sent and t_rx > sent[v]:
            t_pub = sent.pop(v)
            _LAT.append(t_src - t_pub)
            _SEEN.append(t_rx - t_pub)


if __name__ == "__main__":
    sys.exit(main())

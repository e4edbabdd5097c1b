#!/usr/bin/env python3
"""What rclpy's default QoS event handlers cost a process that takes messages (docs/benchmarks.md, "QoS event
handlers"): one node with ``--readers`` raw readers (as the demo's recorder and monitor hold about 45), a writer on one
of their topics, and for each message published the time until rclpy's executor has taken it
(``SingleThreadedExecutor.spin_once``, publication included), with the readers made

* ``default``: as rclpy makes them (two event handlers each: incompatible QoS, incompatible type);
* ``one``: one handler each (incompatible QoS only);
* ``none``: without (``avp_common.qos.QUIET_READER``, what the graph's readers use).

Each handler is a waitable the executor walks in Python, and Fast DDS attaches to its wait set, for every message it
takes. Printed: the mean time per message over ``--messages`` messages, best of ``--repeats``, per variant.

Usage: python bench/bench_executor_events.py [--readers 45] [--messages 2000] [--repeats 3]
"""

from __future__ import annotations

import argparse
import platform
import sys
import time


def per_message_ms(variant: str, readers: int, messages: int) -> tuple[float, int]:
    """Mean ms per message taken by a node of ``readers`` readers made as ``variant``; (ms, waitables of the node)."""
    import rclpy
    from rclpy.event_handler import SubscriptionEventCallbacks
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import String

    from avp_common.qos import QUIET_READER, QUIET_WRITER, STEP

    events = {"default": None, "one": SubscriptionEventCallbacks(use_default_callbacks=False,
                                                                 incompatible_qos=lambda _e: None),
              "none": QUIET_READER}[variant]
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node(f"bench_events_{variant}", context=context)
        got = [0]
        for i in range(readers):
            node.create_subscription(String, f"/bench_events/t{i}", lambda _m: got.__setitem__(0, got[0] + 1), STEP,
                                     raw=True, event_callbacks=events)
        pub = node.create_publisher(String, "/bench_events/t0", STEP, event_callbacks=QUIET_WRITER)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        t0 = time.monotonic()
        while pub.get_subscription_count() < 1 and time.monotonic() - t0 < 10:
            executor.spin_once(timeout_sec=0.05)
        msg = String(data="x")
        for _ in range(50):  # warm up
            pub.publish(msg)
            executor.spin_once(timeout_sec=1.0)
        got[0] = 0
        t0 = time.perf_counter()
        for _ in range(messages):
            pub.publish(msg)
            executor.spin_once(timeout_sec=1.0)
        dt = time.perf_counter() - t0
        if got[0] != messages:
            raise RuntimeError(f"{variant}: took {got[0]} of {messages} messages")
        waitables = len(list(node.waitables))
        executor.shutdown()
        node.destroy_node()
        return 1e3 * dt / messages, waitables
    finally:
        rclpy.try_shutdown(context=context)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--readers", type=int, default=45, help="readers of the node (the demo's process: about 45)")
    ap.add_argument("--messages", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=3, help="runs per variant, alternating; the best is printed")
    args = ap.parse_args()
    print(f"# {platform.node()} {platform.processor() or platform.machine()}, {args.readers} readers, "
          f"{args.messages} messages, best of {args.repeats}")
    best: dict[str, tuple[float, int]] = {}
    for _ in range(args.repeats):
        for variant in ("default", "one", "none"):
            ms, waitables = per_message_ms(variant, args.readers, args.messages)
            if variant not in best or ms < best[variant][0]:
                best[variant] = (ms, waitables)
    print("| readers made | waitables of the node | ms a message |")
    print("|---|--:|--:|")
    for variant, (ms, waitables) in best.items():
        print(f"| {variant} | {waitables} | {ms:.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

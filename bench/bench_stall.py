#!/usr/bin/env python3
"""Hung nodes in real time: how soon the ego stops after a node hangs, and for how long it holds.

Runs the real-time SIGSTOP test (tests/test_operations.py::test_sigstopped_nodes_in_realtime_hold_the_ego_then_resume:
the belief node, then the prediction node, then the planner SIGSTOPped for 5 s each while the ego drives, seed 3)
and prints its measurements as a table: the step of the SIGSTOP, the steps after it on which the ego still moved
(commands answered before the hang, and the ``stale_input_timeout`` of 0.5 s = 5 steps), and the steps it held.

Usage: python bench/bench_stall.py
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    r = subprocess.run([sys.executable, "-m", "pytest", "-s", "-q", "-p", "no:cacheprovider",
                        "tests/test_operations.py::test_sigstopped_nodes_in_realtime_hold_the_ego_then_resume"],
                       cwd=ROOT, capture_output=True, text=True)
    rows = re.findall(r"\[stall\] (\w+): SIGSTOP at step (\d+), last ego motion (\d+) step\(s\) later, (\d+) steps "
                      r"stalled", r.stdout)
    if r.returncode != 0 or not rows:
        print(r.stdout[-3000:], r.stderr[-3000:], file=sys.stderr)
        return 1
    print("| node hung (SIGSTOP 5 s) | at step | ego still moved for | = time to stop | steps stalled |")
    print("|---|--:|--:|--:|--:|")
    for name, k, moved, stalled in rows:
        print(f"| {name} | {k} | {moved} step(s) | {int(moved) * 0.1:.1f} s | {stalled} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

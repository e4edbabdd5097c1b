"""Issue #20 item 2: a foreign publisher floods `cmd`, `observation` and `beliefs` at 1 kHz each during a lock-step
episode of the full graph (simulator, belief node, prediction node, planner as real processes over real DDS).

The flood (bench/flood_publisher.py, a separate process) cycles untagged, forged-tag, NaN/inf and replayed
(tagged copies of the graph's own latest message) messages. Oracles: the in-process run of the same seed (the
episode must be bit-identical), each node's /proc RSS, each node's log file. The step-time figures under flood
come from bench/bench_flood.py (docs/benchmarks.md), never from an assertion here.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

FLOODER = Path(__file__).resolve().parents[1] / "bench" / "flood_publisher.py"


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def test_rate_limited_log_counts_and_writes_one_line_a_second():
    from avp_common.ratelog import RateLimitedLog, reason_key

    now = {"t": 0.0}
    lines: list[str] = []
    log = RateLimitedLog(lines.append, period=1.0, clock=lambda: now["t"])
    for i in range(3000):  # 3 s of a 1 kHz flood of one kind of bad message
        now["t"] = i / 1000
        log(f"/avp/cmd: command stamped {i} ns is ahead of step 0; dropped")
    log("/avp/cmd: command with NaN/inf (v=nan, omega=0.0) dropped")  # another reason: its own key, logged at once
    assert len(lines) == 4 and lines[0].endswith("is ahead of step 0; dropped")
    assert "[1000 like it since the last line, 2001 in all" in lines[2] and "NaN/inf" in lines[3]
    assert reason_key("step 12 after step 140") == reason_key("step 3 after step 4")


def test_a_flood_on_cmd_observation_and_beliefs_leaves_the_episode_unchanged(paper_lot, ros_env, tmp_path,
                                                                            monkeypatch):
    from test_dds_lockstep import PLANNER_OVERRIDES, PREDICTION_OVERRIDES, SEED, T_FINAL, _inprocess_trajectory

    from avp_bringup.graph import Graph, default_graph, with_params
    from avp_bringup.monitor import EpisodeMonitor

    expected, world, _ = _inprocess_trajectory(paper_lot, "planner", "bezier")
    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    nodes = default_graph("planner")
    nodes[-1] = with_params(nodes[-1], **PLANNER_OVERRIDES)
    nodes[2] = with_params(nodes[2], method="bezier", **PREDICTION_OVERRIDES)
    n_subs = nodes[0].extra_params["min_subscribers"]
    nodes[0] = with_params(nodes[0], seed=SEED, reactive=True, t_final=T_FINAL, publish_markers=False,
                           min_subscribers=n_subs + 1, min_debug_subscribers=1)  # + our monitor
    rclpy.init()
    monitor = EpisodeMonitor()
    graph = Graph(nodes, tmp_path / "logs", env=ros_env)
    flood = subprocess.Popen([sys.executable, str(FLOODER), "--rate", "1000", "--duration", "600"], env=ros_env,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    graph.start()
    rss: dict[str, list[float]] = {name: [] for name in graph.procs}
    try:
        t0 = last = time.monotonic()
        while not monitor.finished and time.monotonic() - t0 < 300:
            rclpy.spin_once(monitor, timeout_sec=0.05)
            assert all(rc is None for rc in graph.poll().values()), "a node died under the flood"
            if time.monotonic() - last >= 1.0:
                last = time.monotonic()
                for name, p in graph.procs.items():
                    rss[name].append(_rss_mb(p.pid))
        assert monitor.finished, "episode did not finish under the flood"
        wall = time.monotonic() - t0
        t1 = time.monotonic()
        while len(monitor.gt) < monitor.status.step + 1 and time.monotonic() - t1 < 10:
            rclpy.spin_once(monitor, timeout_sec=0.05)
        got = monitor.ego_trajectory()
        assert all(rc is None for rc in graph.poll().values())
    finally:
        flood.send_signal(signal.SIGTERM)
        out, err = flood.communicate(timeout=30)
        graph.stop()
        monitor.destroy_node()
        rclpy.try_shutdown()
    report = json.loads(out.strip().splitlines()[-1])
    sent = {t: sum(k.values()) for t, k in report["sent"].items()}
    assert all(n >= 1000 for n in sent.values()), (report, err)  # it did flood (the rate depends on the machine)
    assert all(k["replay"] > 0 for k in report["sent"].values()), report  # tagged copies of the graph's messages
    assert got.shape == expected.shape and np.array_equal(got, expected)  # the same episode as without the flood
    logs = {p.stem: p.read_text() for p in (tmp_path / "logs").glob("*.log")}
    flooded = {"avp_sim": 1, "avp_belief": 1, "avp_prediction": 1, "avp_planner": 2}  # flooded inputs per node
    for name, n_topics in flooded.items():
        lines = logs[name].splitlines()
        assert sum("unauthenticated message(s) dropped" in ln for ln in lines) >= 1, name
        # at most one line a second per flooded topic (plus one per newly seen publisher)
        assert len(lines) <= n_topics * (wall + 5) + 20, (name, len(lines), wall)
    for name, series in rss.items():
        settled = series[3:] or series
        assert max(settled) - settled[0] < 150, (name, series)  # bounded (queues are bounded): no growth with time

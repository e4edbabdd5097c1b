"""A foreign publisher floods `cmd`, `observation` and `beliefs` at 1 kHz each during a lock-step
episode of the full graph (simulator, belief node, prediction node, planner as real processes over real DDS).

The flood (bench/flood_publisher.py, a separate process) cycles untagged, forged-tag, NaN/inf and replayed (tagged
copies of the graph's own latest message) messages, and copies of the first message it saw on each topic
(the running episode's step 0) and messages re-tagged as of the episode before (a replayed bag), and calls the
simulator's reset_episode twice a second with hostile requests (bench/hostile_requests.py). Oracles: the in-process
run of the same seed (the episode must be bit-identical), each node's /proc RSS, each node's log file. The step-time
figures under flood come from bench/bench_flood.py (docs/benchmarks.md), never from an assertion here.
"""

from __future__ import annotations

import json
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

FLOODER = Path(__file__).resolve().parents[1] / "bench" / "flood_publisher.py"
#: messages a second on each flooded topic in the full-graph test (see there)
FLOOD_RATE = 200


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
    from avp_monitor.monitor import EpisodeMonitor

    # the planner with the agents' reaction assumed only once seen (profile wary), the compute profile this test was
    # set up with: the default's roll-out for every agent costs more per decision. On 2 loaded cores the flooded
    # pipeline has needed the 5 s lock-step re-send at many steps with either planner (docs/benchmarks.md)
    planner = {**PLANNER_OVERRIDES, "collision.reactive_evidence": "lot"}
    expected, world, _ = _inprocess_trajectory(paper_lot, "planner", "bezier", planner)
    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    nodes = default_graph("planner")
    nodes[-1] = with_params(nodes[-1], **planner)
    nodes[2] = with_params(nodes[2], method="bezier", **PREDICTION_OVERRIDES)
    n_subs = nodes[0].extra_params["min_subscribers"]
    nodes[0] = with_params(nodes[0], seed=SEED, reactive=True, t_final=T_FINAL, publish_markers=False,
                           min_subscribers=n_subs + 1, min_debug_subscribers=1)  # + our monitor
    rclpy.init()
    monitor = EpisodeMonitor()
    graph = Graph(nodes, tmp_path / "logs", env=ros_env)
    # FLOOD_RATE per topic, not 1 kHz: at 1 kHz on each of three topics 2 cores are saturated (docs/benchmarks.md,
    # "Hung nodes and floods"), the nodes' reader queues overflow, real messages of a step are lost now and then
    # (about one step in ten on an idle 2-core machine) and each loss waits for the 5 s lock-step re-send, so the
    # episode's wall time grew past any limit under load. What this test checks is that hostile messages change
    # nothing, and that holds at any rate; the 1 kHz behaviour is bench/bench_flood.py's
    flood = subprocess.Popen([sys.executable, str(FLOODER), "--rate", str(FLOOD_RATE), "--duration", "600",
                              "--episode-replays", "--bad-resets", "2"], env=ros_env,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # the graph starts once the flood is on: on a loaded machine the flooder takes seconds to start, and an episode
    # that ended first would never have been flooded (it happened with four test processes beside two CPU hogs)
    ready, _, _ = select.select([flood.stdout], [], [], 180)
    assert ready and flood.stdout.readline().strip() == "flooding", "the flooder did not start"
    graph.start()
    rss: dict[str, list[float]] = {name: [] for name in graph.procs}
    try:
        t0 = last = time.monotonic()
        # a generous limit (the episode takes about 1-3 min on 2 cores)
        while not monitor.finished and time.monotonic() - t0 < 600:
            rclpy.spin_once(monitor, timeout_sec=0.05)
            assert all(rc is None for rc in graph.poll().values()), "a node died under the flood"
            # RSS once a second from the episode's step 10 on: before that the nodes still import and load (the
            # belief node's torch and intent CNN take > 300 MB, and 10 s or more on a loaded 2-core machine)
            if monitor.status is not None and monitor.status.step >= 10 and time.monotonic() - last >= 1.0:
                last = time.monotonic()
                for name, p in graph.procs.items():
                    rss[name].append(_rss_mb(p.pid))
        assert monitor.finished, "episode did not finish under the flood"
        wall = time.monotonic() - t0
        t1 = time.monotonic()
        while len(monitor.gt) < monitor.status.step + 1 and time.monotonic() - t1 < 30:
            rclpy.spin_once(monitor, timeout_sec=0.05)
        got = monitor.ego_trajectory()
        assert all(rc is None for rc in graph.poll().values())
    finally:
        flood.send_signal(signal.SIGTERM)
        out, err = flood.communicate(timeout=30)
        graph.stop()
        monitor.destroy_node()
        rclpy.try_shutdown()
    assert out.strip(), f"the flooder printed no report (exit {flood.returncode}): {err[-3000:]}"
    report = json.loads(out.strip().splitlines()[-1])
    sent = {t: sum(k.values()) for t, k in report["sent"].items()}
    # it did flood: at least 100 messages on each topic, at no less than 10 % of the asked rate, twice the graph's own
    # 10 Hz (the achieved rate is the machine's: 71-75 % beside two CPU hogs on one 2-core machine, 28-31 % beside
    # two hogs and another DDS test on one twice as slow); an episode can end within 5 s of flood
    assert all(n >= 100 for n in sent.values()), (report, err)
    assert all(r >= 0.1 * FLOOD_RATE for r in report["rate_hz"].values()), (report, err)
    assert all(k["replay"] > 0 for k in report["sent"].values()), report  # tagged copies of the graph's messages
    # the running episode's first messages (step 0) replayed, and messages of the episode before
    assert all(k["replay_first"] > 0 and k["earlier_episode"] > 0 for k in report["sent"].values()), report
    # and a stream of hostile reset_episode requests: 2 a second while the service is up, so their number follows
    # the episode's wall time (a fixed count failed when the episode ended within 10 s); at least 1 a second
    assert report["bad_resets"] >= max(4, report["wall_s"] - 2), report
    assert got.shape == expected.shape and np.array_equal(got, expected)  # the same episode as without the flood
    logs = {p.stem: p.read_text() for p in (tmp_path / "logs").glob("*.log")}
    flooded = {"avp_sim": 2, "avp_belief": 1, "avp_prediction": 1, "avp_planner": 2}  # flooded inputs per node
    for name, n_topics in flooded.items():
        lines = logs[name].splitlines()
        assert sum("unauthenticated message(s) dropped" in ln for ln in lines) >= 1, name
        # at most one line a second per flooded input and reason (a foreign tag; a replayed step 0 of the running
        # episode; a message of the episode before), plus one per newly seen publisher
        assert len(lines) <= 3 * n_topics * (wall + 5) + 20, (name, len(lines), wall)
    for name, series in rss.items():
        settled = series[3:] or series or [0.0]  # the first forward passes may still allocate
        print(f"[rss] {name}: {' '.join(f'{v:.0f}' for v in series)} MB")  # pytest -s
        assert max(settled) - settled[0] < 150, (name, series)  # bounded (queues are bounded): no growth with time


def test_planner_stops_cleanly_under_a_flood_and_drops_oversized_inputs_unread(ros_env, tmp_path, monkeypatch):
    """A planner flooded at 1 kHz on `observation` and `beliefs` exits 0 on SIGINT with
    no traceback, three times over (the take interrupted by the signal was once printed as a pybind11
    RuntimeError); and an input larger than MAX_INPUT_BYTES is dropped before its tag is checked, with one line."""
    import numpy as np

    from avp_bringup.graph import Graph, NodeSpec
    from avp_common.msg_auth import MAX_INPUT_BYTES
    from avp_common.qos import STEP
    from avp_msgs.msg import Observation

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    spec = NodeSpec("avp_planner", "avp_planner", "planner", "config/planner.param.yaml")
    rclpy.init()
    node = rclpy.create_node("oversized", namespace="/avp")
    pub = node.create_publisher(Observation, "observation", STEP)
    try:
        for run in range(3):
            logs = tmp_path / f"run{run}"
            flood = subprocess.Popen([sys.executable, str(FLOODER), "--rate", "1000", "--duration", "600",
                                      "--topics", "/avp/observation,/avp/beliefs"], env=ros_env,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            graph = Graph([spec], logs, env=ros_env)
            graph.start()
            try:
                t0 = time.monotonic()
                while time.monotonic() - t0 < 60 and "unauthenticated" not in _text(logs / "avp_planner.log"):
                    time.sleep(0.2)
                assert "unauthenticated" in _text(logs / "avp_planner.log"), "the flood did not reach the planner"
                if run == 0:  # ~18 MB of ray ranges: over the cap
                    big = Observation()
                    big.ray_ranges = np.zeros(MAX_INPUT_BYTES // 4 + 1000, dtype=np.float32)
                    t0 = time.monotonic()
                    while time.monotonic() - t0 < 60 and "dropped unread" not in _text(logs / "avp_planner.log"):
                        pub.publish(big)
                        rclpy.spin_once(node, timeout_sec=1.0)
                proc = graph.procs["avp_planner"]
                proc.send_signal(signal.SIGINT)
                proc.wait(timeout=60)
                assert proc.returncode == 0, (run, proc.returncode)
            finally:
                graph.stop()
                flood.send_signal(signal.SIGTERM)
                flood.communicate(timeout=30)
            log = _text(logs / "avp_planner.log")
            assert "Traceback" not in log and "RuntimeError" not in log, (run, log[-2000:])
            if run == 0:
                assert f"larger than {MAX_INPUT_BYTES} bytes, dropped unread message(s) dropped" in log
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def _text(path: Path) -> str:
    return path.read_text() if path.exists() else ""

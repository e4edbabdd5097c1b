"""``avp experiment --transport ros``: the same episodes through the live DDS graph.

Per method one graph is started (:func:`avp_bringup.graph.method_graph`: the simulator in lock-step with
``autostart`` off, the belief node, the prediction node and the planner, each configured from the method's
profile, wall-clock caps lifted), and each episode is started with the simulator's ``reset_episode`` service
(seed, reactive). A collector node in this process records what the runner needs and the ego never sees:
``episode_status`` (the simulator's §VI-B metrics), ``debug/ground_truth`` (every vehicle's state per step, for
minADE/minFDE), the prediction node's ``predictions``, the planner's ``decision`` (timings) and the publication
times of ``observation`` and ``predictions``. The record is built by the same function as in-process
(:func:`~.metrics.episode_record`), so both transports give identical records apart from the timings.

Timings: the perception runs in two other processes, so its share of the spot-selection time is measured on
the critical path — the DDS source timestamps of predictions k minus observation k (belief node, prediction
node and two hops) — and added to the planner's own spot-selection time from ``decision``. In-process timings
(``--transport inproc``) are pure compute and are the ones to compare with Table I. Slow (one episode at a time,
~10-20 ms per DDS round trip); meant for the equivalence test.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from avp_experiment.protocols import load_protocol
from avp_experiment.run_config import Key, RunConfig, run_profile, sim_values

DRAIN_S = 10.0  # wall seconds to wait for the last messages after the episode ended


def run_ros(keys: list[Key], cfg: RunConfig, on_record: Callable[[dict], None], log_dir: Path,
            timeout: float = 600.0, env: dict | None = None) -> None:
    """Run ``keys`` through the live graph, one method graph after the other (see the module docstring)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from avp_bringup.graph import Graph, method_graph
    from avp_common.services import call_once
    from avp_experiment.metrics import lot_record
    from avp_experiment.ros_collector import EpisodeCollector
    from avp_msgs.srv import ResetEpisode
    from avp_sim.core.factory import load_lot_param

    if not cfg.message_precision:
        raise ValueError("--float64-messages applies to --transport inproc only (the graph's messages are float32)")
    sim_p = sim_values(cfg)
    sim_extra = ({k: sim_p[k] for k in ("t_final", "dt", "t_hist")} | load_protocol(cfg.protocol).sim
                 | dict(cfg.sim_overrides))
    by_method: dict[str, list[Key]] = {}
    for k in keys:
        by_method.setdefault(k[0], []).append(k)
    rclpy.init()
    collector = EpisodeCollector(lot_record(load_lot_param(sim_p["lot_file"])))
    executor = SingleThreadedExecutor()
    executor.add_node(collector)
    client = collector.create_client(ResetEpisode, "reset_episode")
    try:
        for method, mkeys in by_method.items():
            nodes = method_graph(run_profile(method, cfg), deterministic=True, intent_weights=cfg.intent_weights,
                                 intent_seed=cfg.intent_seed, sim_extra={
                                     **sim_extra, "autostart": False, "publish_markers": False,
                                     "min_debug_subscribers": 1})
            graph = Graph(nodes, Path(log_dir) / method, env=env)
            graph.start()
            try:
                t0 = time.monotonic()
                # the simulator's step 0 waits for the ego's observation subscription; the ego's outputs must reach
                # us from step 0 on too: wait until its publishers are discovered (then a moment for matching)
                while not (client.wait_for_service(timeout_sec=0.2) and collector.ego_publishers_ready()):
                    executor.spin_once(timeout_sec=0.05)
                    _check_alive(graph, log_dir, method)
                    if time.monotonic() - t0 > 60:
                        raise RuntimeError(f"graph not up after 60 s (reset_episode service, pipeline publishers);"
                                           f" logs in {log_dir}/{method}")
                t1 = time.monotonic()
                while time.monotonic() - t1 < 0.5:
                    executor.spin_once(timeout_sec=0.05)
                for _, seed, mode in mkeys:
                    reactive = mode == "reactive"
                    collector.begin(seed, reactive)
                    t0 = time.monotonic()
                    try:  # sent once; the episode's own status also shows that the reset happened
                        res = call_once(client, ResetEpisode.Request(seed=int(seed), reactive=reactive),
                                        lambda s: executor.spin_once(timeout_sec=s),
                                        lambda: collector.status is not None, timeout=30.0)
                    except TimeoutError as exc:
                        raise RuntimeError(f"reset_episode(seed={seed}, reactive={reactive}) failed: {exc}") from None
                    if res is not None and not res.success:
                        raise RuntimeError(f"reset_episode(seed={seed}, reactive={reactive}) failed: {res.message}")
                    t_end = None
                    while not collector.finished:
                        executor.spin_once(timeout_sec=0.1)
                        _check_alive(graph, log_dir, method)
                        if collector.ended and t_end is None:
                            t_end = time.monotonic()
                        if t_end is not None and time.monotonic() - t_end > DRAIN_S:
                            missing = {k: v[:10] for k, v in collector.missing().items() if v}
                            raise RuntimeError(f"{method} seed {seed} {mode}: the episode ended but messages of steps "
                                               f"{missing} never arrived; logs in {log_dir}/{method}")
                        if time.monotonic() - t0 > timeout:
                            raise RuntimeError(f"{method} seed {seed} {mode}: no complete episode after {timeout} s "
                                               f"wall time; logs in {log_dir}/{method}")
                    on_record(collector.record(method, cfg.ade_horizon, time.monotonic() - t0))
            finally:
                graph.stop()
    finally:
        collector.destroy_node()
        rclpy.try_shutdown()


def _check_alive(graph, log_dir: Path, method: str) -> None:
    dead = {n: rc for n, rc in graph.poll().items() if rc is not None}
    if dead:
        raise RuntimeError(f"node(s) exited: {dead}; see {Path(log_dir) / method}/")

"""``avp experiment --transport ros``: the same episodes through the live DDS graph.

Per method one graph is started (:func:`avp_bringup.graph.method_graph`: the simulator in lock-step with
``autostart`` off, the belief node, the prediction node and the planner, each configured from the method's
profile, wall-clock caps lifted), and each episode is started with the simulator's ``reset_episode`` service
(seed, reactive). A collector node in this process records what the runner needs and the ego never sees:
``episode_status`` (the simulator's §VI-B metrics), ``debug/ground_truth`` (every vehicle's state per step, for
minADE/minFDE), the prediction node's ``predictions``, the planner's ``decision`` (timings) and the publication
times of ``observation`` and ``predictions``. The record is built by the same function as in-process
(:func:`~.metrics.episode_record`), so both transports give identical records apart from the timings.

Several egos (``--egos K``, ``--fleet``): one fleet graph per fleet (:func:`avp_bringup.graph.fleet_graph`: the
simulator with ``egos.count`` K, K pipelines in ``/avp/ego<i>``), recorded by
:class:`avp_experiment_ros.fleet_collector.FleetCollector`, a record per ego with the in-process fleet's fields.

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

from avp_episode.protocols import load_protocol
from avp_episode.run_config import Key, RunConfig, run_profile, sim_values

#: wall seconds to wait for the next of the last messages after the episode ended: a collector behind a loaded
#: machine's graph sees the episode's status (a topic of its own) before the backlog of the others
DRAIN_S = 10.0


def run_ros(keys: list[Key], cfg: RunConfig, on_record: Callable, log_dir: Path,
            timeout: float = 600.0, env: dict | None = None) -> None:
    """Run ``keys`` through the live graph, one graph per method (or fleet: :func:`avp_bringup.graph.fleet_graph`,
    recorded by :class:`avp_experiment_ros.fleet_collector.FleetCollector`, a list of records per episode) after the
    other (see the module docstring)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from avp_bringup.graph import fleet_graph, method_graph
    from avp_episode.fleet import fleet_names
    from avp_episode.metrics import lot_record
    from avp_experiment_ros.collector import EpisodeCollector
    from avp_experiment_ros.fleet_collector import FleetCollector
    from avp_sim.core.factory import load_lot_param

    if not cfg.message_precision:
        raise ValueError("--float64-messages applies to --transport inproc only (the graph's messages are float32)")
    sim_p = sim_values(cfg)
    sim_extra = ({k: sim_p[k] for k in ("t_final", "dt", "t_hist")} | load_protocol(cfg.protocol).sim
                 | dict(cfg.sim_overrides))
    sim_extra |= {"autostart": False, "publish_markers": False, "min_debug_subscribers": 1}
    by_unit: dict[str, list[Key]] = {}
    for k in keys:
        by_unit.setdefault(k[0], []).append(k)
    lot = load_lot_param(sim_p["lot_file"])
    intent = {"intent_weights": cfg.intent_weights, "intent_seed": cfg.intent_seed}
    rclpy.init()
    executor = SingleThreadedExecutor()
    try:
        for unit, ukeys in by_unit.items():
            names = fleet_names(unit)
            if names:  # K egos: the simulator's egos.* as in process (sim_values), the K pipelines
                profiles = [run_profile(n, cfg) for n in names]
                egos = {k: v for k, v in sim_p.items() if k.startswith("egos.") and k != "egos.count"}
                nodes = fleet_graph(profiles, deterministic=True, sim_extra={**egos, **sim_extra}, **intent)
                collector = FleetCollector(len(names), lot, lot_record(lot))
                ready, started = collector.publishers_ready, lambda c=collector: c.lot_status is not None

                def record(wall: float, c=collector, p=profiles, u=unit) -> list[dict]:
                    return c.records(p, u, cfg.ade_horizon, wall)
            else:
                nodes = method_graph(run_profile(unit, cfg), deterministic=True, sim_extra=sim_extra, **intent)
                collector = EpisodeCollector(lot_record(lot))
                ready, started = collector.ego_publishers_ready, lambda c=collector: c.status is not None

                def record(wall: float, c=collector, u=unit) -> dict:
                    return c.record(u, cfg.ade_horizon, wall)
            executor.add_node(collector)
            try:
                _run_graph(nodes, collector, executor, ukeys, ready, started, record, on_record,
                           Path(log_dir) / _log_name(unit), timeout, env)
            finally:
                executor.remove_node(collector)
                collector.destroy_node()
    finally:
        rclpy.try_shutdown()


def _log_name(unit: str) -> str:
    """A folder name for the logs of ``unit`` (a method, or ``fleet:a,b``)."""
    return unit.replace(":", "_").replace(",", "+")


def _run_graph(nodes, collector, executor, keys: list[Key], ready: Callable[[], bool], started: Callable[[], bool],
               record: Callable[[float], dict | list[dict]], on_record: Callable, logs: Path, timeout: float,
               env: dict | None) -> None:
    """Start ``nodes``, wait until the simulator's ``reset_episode`` and the publishers ``ready`` names are up, then
    run each key's episode with ``reset_episode`` and hand ``record`` of it to ``on_record``."""
    from avp_bringup.graph import Graph
    from avp_common.services import call_once
    from avp_msgs.srv import ResetEpisode

    client = collector.create_client(ResetEpisode, "reset_episode")
    graph = Graph(nodes, logs, env=env)
    graph.start()
    try:
        t0 = time.monotonic()
        # the simulator's step 0 waits for the ego's observation subscription; the ego's outputs must reach us from
        # step 0 on too: wait until its publishers are discovered (then a moment for matching)
        while not (client.wait_for_service(timeout_sec=0.2) and ready()):
            executor.spin_once(timeout_sec=0.05)
            _check_alive(graph, logs)
            if time.monotonic() - t0 > 60:
                raise RuntimeError(f"graph not up after 60 s (reset_episode service, pipeline publishers); logs in "
                                   f"{logs}")
        t1 = time.monotonic()
        while time.monotonic() - t1 < 0.5:
            executor.spin_once(timeout_sec=0.05)
        for unit, seed, mode in keys:
            reactive = mode == "reactive"
            collector.begin(seed, reactive)
            t0 = time.monotonic()
            try:  # sent once; the episode's own status also shows that the reset happened
                res = call_once(client, ResetEpisode.Request(seed=int(seed), reactive=reactive),
                                lambda s: executor.spin_once(timeout_sec=s), started, timeout=30.0)
            except TimeoutError as exc:
                raise RuntimeError(f"reset_episode(seed={seed}, reactive={reactive}) failed: {exc}") from None
            if res is not None and not res.success:
                raise RuntimeError(f"reset_episode(seed={seed}, reactive={reactive}) failed: {res.message}")
            t_end, left = None, None
            while True:
                executor.spin_once(timeout_sec=0.1)
                _check_alive(graph, logs)
                if collector.ended:  # the status can overtake a backlog of other topics: wait while it drains
                    missing = collector.missing()
                    now_left = sum(len(v) for v in missing.values())
                    if now_left == 0:
                        break
                    if now_left != left:  # a message arrived (a fleet's count can grow: decisions are counted
                        t_end, left = time.monotonic(), now_left  # once the ground truth is complete)
                    if time.monotonic() - t_end > DRAIN_S:
                        missing = {k: v[:10] for k, v in missing.items() if v}
                        raise RuntimeError(f"{unit} seed {seed} {mode}: the episode ended but messages of steps "
                                           f"{missing} never arrived; logs in {logs}")
                if time.monotonic() - t0 > timeout:
                    raise RuntimeError(f"{unit} seed {seed} {mode}: no complete episode after {timeout} s wall "
                                       f"time; logs in {logs}")
            on_record(record(time.monotonic() - t0))
    finally:
        graph.stop()


def _check_alive(graph, logs: Path) -> None:
    dead = {n: rc for n, rc in graph.poll().items() if rc is not None}
    if dead:
        raise RuntimeError(f"node(s) exited: {dead}; see {logs}/")

"""Integration: a short episode through real processes over DDS in lock-step equals the in-process core.

Starts the real sim_node and scripted_driver executables (separate processes, real DDS on a domain
id of this test's own) and a monitor node in this process; compares the ego trajectory received on
debug/ground_truth with an in-process run of the same cores for the same seed.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

SEED = 5
T_FINAL = 6.0


def _inprocess_trajectory(lot):
    from ament_index_python.packages import get_package_share_directory as share

    from avp_bringup.inproc import run_episode
    from avp_common.params import load_yaml_params
    from avp_planner.scripted_driver import ScriptedDriver, ScriptedDriverConfig
    from avp_planner.scripted_driver_node import DRIVER_PARAMS
    from avp_sim.core.factory import make_world
    from avp_sim.params import SIM_PARAMS

    p = load_yaml_params(f"{share('avp_sim')}/config/sim.param.yaml", "avp_sim", SIM_PARAMS)
    p["t_final"] = T_FINAL
    d = load_yaml_params(f"{share('avp_planner')}/config/scripted_driver.param.yaml", "scripted_driver",
                         DRIVER_PARAMS)
    world = make_world(lot, p, SEED, True)
    driver = ScriptedDriver(lot, ScriptedDriverConfig(**d))
    run_episode(world, driver.command)
    return np.array(world.log_ego), world


def test_lockstep_over_dds_matches_inprocess(paper_lot, ros_env, tmp_path, monkeypatch):
    from avp_bringup.graph import Graph, default_graph
    from avp_bringup.monitor import EpisodeMonitor

    expected, world = _inprocess_trajectory(paper_lot)
    assert len(expected) == int(T_FINAL / 0.1) + 1 or world.done

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    nodes = default_graph()
    sim = nodes[0]
    nodes[0] = type(sim)(sim.name, sim.package, sim.executable, sim.param_file,
                         {"seed": SEED, "reactive": True, "t_final": T_FINAL, "publish_markers": False})
    rclpy.init()
    monitor = EpisodeMonitor()
    graph = Graph(nodes, tmp_path / "logs", env=ros_env)
    graph.start()
    try:
        t0 = time.monotonic()
        while not monitor.finished and time.monotonic() - t0 < 120:
            rclpy.spin_once(monitor, timeout_sec=0.1)
            assert all(rc is None for rc in graph.poll().values()), (tmp_path / "logs").glob("*.log")
        for _ in range(20):
            rclpy.spin_once(monitor, timeout_sec=0.05)
        assert monitor.finished, "episode did not finish over DDS"
        got = monitor.ego_trajectory()
    finally:
        graph.stop()
        monitor.destroy_node()
        rclpy.try_shutdown()
    assert got.shape == expected.shape
    assert np.array_equal(got, expected)  # bit-identical: lock-step makes the result independent of timing
    assert monitor.metrics_dict()["steps"] == world.metrics.steps

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
T_FINAL = 15.0
# the planner's wall-clock caps are its only timing-dependent knobs: lift them so the iteration caps decide
PLANNER_OVERRIDES = {"search.time_cap": 30.0, "decision.decision_time_cap": 60.0}


def _inprocess_trajectory(lot, ego):
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
    if ego == "scripted":
        driver = ScriptedDriver(lot, ScriptedDriverConfig(**d))
        run_episode(world, driver.command)
    else:
        from avp_common.params import dataclass_from_values
        from avp_planner.core.decision import EgoPlanner
        from avp_planner.core.settings import DEFAULT_SETTINGS
        from avp_planner.planner_node import PLANNER_PARAMS

        q = load_yaml_params(f"{share('avp_planner')}/config/planner.param.yaml", "avp_planner", PLANNER_PARAMS)
        q.update(PLANNER_OVERRIDES)
        planner = EgoPlanner(lot, dataclass_from_values(DEFAULT_SETTINGS, q))
        run_episode(world, lambda obs: planner.decide(obs, None, []).command)
    return np.array(world.log_ego), world


@pytest.mark.parametrize("ego", ["scripted", "planner"])
def test_lockstep_over_dds_matches_inprocess(paper_lot, ros_env, tmp_path, monkeypatch, ego):
    from avp_bringup.graph import Graph, default_graph
    from avp_bringup.monitor import EpisodeMonitor

    expected, world = _inprocess_trajectory(paper_lot, ego)
    assert len(expected) == int(T_FINAL / 0.1) + 1 or world.done

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    nodes = default_graph(ego)
    if ego == "planner":
        nodes[1] = type(nodes[1])(nodes[1].name, nodes[1].package, nodes[1].executable, nodes[1].param_file,
                                  PLANNER_OVERRIDES)
    sim = nodes[0]
    nodes[0] = type(sim)(sim.name, sim.package, sim.executable, sim.param_file,
                         {"seed": SEED, "reactive": True, "t_final": T_FINAL, "publish_markers": False,
                          "min_subscribers": 2, "min_debug_subscribers": 1})  # ego node + our monitor must see step 0
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

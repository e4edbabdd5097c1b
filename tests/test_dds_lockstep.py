"""Integration: a short episode through real processes over DDS in lock-step equals the in-process core.

Starts the real node executables of ``default_graph`` (separate processes, real DDS on a domain id of this
test's own) and a monitor node in this process; compares the ego trajectory received on
debug/ground_truth with an in-process run of the same cores for the same seed:

* ``scripted``: sim + scripted driver;
* ``planner``: the full graph — sim, belief node, prediction node (Bezier), planner waiting for beliefs and
  predictions — against the in-process ego chain (:func:`avp_episode.inproc.perception_planner`: a MethodEgo);
* ``planner-hybrid_astar``: the same with the prediction node's Hybrid A* predictor.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

SEED = 11  # the ego meets dynamic vehicles whose intentions condition predictions, and parks at ~16 s
T_FINAL = 20.0
# the planner's wall-clock caps are its only timing-dependent knobs: lift them so the iteration caps decide
PLANNER_OVERRIDES = {"search.time_cap": 30.0, "decision.decision_time_cap": 60.0}
PREDICTION_OVERRIDES = {"hybrid_astar.time_cap": 30.0}  # likewise for the Hybrid A* predictor's safety net


def _share(pkg: str, rel: str) -> str:
    from ament_index_python.packages import get_package_share_directory

    return f"{get_package_share_directory(pkg)}/{rel}"


def _inprocess_trajectory(lot, ego, method, planner_overrides=None):
    from avp_common.params import load_yaml_params
    from avp_episode.inproc import run_episode
    from avp_planner.scripted_driver import ScriptedDriver, ScriptedDriverConfig
    from avp_planner.scripted_driver_node import DRIVER_PARAMS
    from avp_sim.core.factory import make_world
    from avp_sim.params import SIM_PARAMS

    p = load_yaml_params(_share("avp_sim", "config/sim.param.yaml"), "avp_sim", SIM_PARAMS)
    p["t_final"] = T_FINAL
    world = make_world(lot, p, SEED, True)
    if ego == "scripted":
        d = load_yaml_params(_share("avp_planner", "config/scripted_driver.param.yaml"), "scripted_driver",
                             DRIVER_PARAMS)
        driver = ScriptedDriver(lot, ScriptedDriverConfig(**d))
        run_episode(world, driver.command)
        return np.array(world.log_ego), world, None
    from avp_common.params import dataclass_from_values
    from avp_episode.inproc import perception_planner
    from avp_motion.settings import DEFAULT_SETTINGS
    from avp_perception.params import BELIEF_PARAMS, PREDICTION_PARAMS
    from avp_planner.planner_node import PLANNER_PARAMS

    q = load_yaml_params(_share("avp_planner", "config/planner.param.yaml"), "avp_planner", PLANNER_PARAMS)
    q.update(PLANNER_OVERRIDES if planner_overrides is None else planner_overrides)
    b = load_yaml_params(_share("avp_perception", "config/belief.param.yaml"), "avp_belief", BELIEF_PARAMS)
    r = load_yaml_params(_share("avp_perception", "config/prediction.param.yaml"), "avp_prediction",
                         PREDICTION_PARAMS)
    r.update(PREDICTION_OVERRIDES, method=method)
    ego_pipeline = perception_planner(lot, b, r, dataclass_from_values(DEFAULT_SETTINGS, q))
    modes = []
    n_pred = []  # per step: predicted trajectories conditioned on an intention (goal set)

    def controller(obs):
        cmd = ego_pipeline(obs)
        modes.append(ego_pipeline.last.decision.mode)
        n_pred.append(sum(p.goal is not None for p in ego_pipeline.last.predictions))
        return cmd

    run_episode(world, controller)
    return np.array(world.log_ego), world, (modes, n_pred)


@pytest.mark.parametrize("case", ["scripted", "planner", "planner-hybrid_astar"])
def test_lockstep_over_dds_matches_inprocess(paper_lot, ros_env, tmp_path, monkeypatch, case):
    from avp_bringup.graph import Graph, default_graph, with_params
    from avp_monitor.monitor import EpisodeMonitor

    ego, _, method = case.partition("-")
    method = method or "bezier"
    expected, world, info = _inprocess_trajectory(paper_lot, ego, method)
    assert len(expected) == int(T_FINAL / 0.1) + 1 or world.done
    if info is not None:  # the reference run must exercise the pipeline: conditioned predictions, parking
        modes, n_pred = info
        assert max(n_pred) > 0 and "park" in modes and world.metrics.success

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    nodes = default_graph(ego)
    names = [n.name for n in nodes]
    if ego == "planner":
        assert names == ["avp_sim", "avp_belief", "avp_prediction", "avp_planner"]
        assert nodes[-1].extra_params == {"use_beliefs": True, "use_predictions": True}
        nodes[-1] = with_params(nodes[-1], **PLANNER_OVERRIDES)
        nodes[2] = with_params(nodes[2], method=method, **PREDICTION_OVERRIDES)
    n_obs_subs = nodes[0].extra_params["min_subscribers"]
    assert n_obs_subs == len(nodes) - 1
    nodes[0] = with_params(nodes[0], seed=SEED, reactive=True, t_final=T_FINAL, publish_markers=False,
                           min_subscribers=n_obs_subs + 1, min_debug_subscribers=1)  # + our monitor
    rclpy.init()
    monitor = EpisodeMonitor()
    graph = Graph(nodes, tmp_path / "logs", env=ros_env)
    graph.start()
    try:
        t0 = time.monotonic()
        while not monitor.finished and time.monotonic() - t0 < 180:
            rclpy.spin_once(monitor, timeout_sec=0.1)
            assert all(rc is None for rc in graph.poll().values()), (tmp_path / "logs").glob("*.log")
        assert monitor.finished, "episode did not finish over DDS"
        t1 = time.monotonic()  # drain: the ground truth of every step up to the final status
        while len(monitor.gt) < monitor.status.step + 1 and time.monotonic() - t1 < 30:
            rclpy.spin_once(monitor, timeout_sec=0.05)
        got = monitor.ego_trajectory()
    finally:
        graph.stop()
        monitor.destroy_node()
        rclpy.try_shutdown()
    missing = sorted(set(range(len(expected))) - set(monitor.gt))
    assert got.shape == expected.shape, f"ground truth of steps {missing[:10]} not received"
    assert np.array_equal(got, expected)  # bit-identical: lock-step makes the result independent of timing
    assert monitor.metrics_dict()["steps"] == world.metrics.steps

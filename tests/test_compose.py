"""One process per ego (avp_bringup.compose, avp_common.container): which nodes share a component container, that
each keeps the ROS arguments of its own process, and the container's one-line errors. Over DDS:
tests/test_fleet_dds.py (K = 2 in containers equal to in-process; one ego's planner swapped out of its container)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("rclpy")

from avp_bringup.compose import ContainerSpec, layout, one_process_per_ego  # noqa: E402
from avp_bringup.graph import Graph, fleet_graph  # noqa: E402
from avp_common.container import main as container_main  # noqa: E402
from avp_common.container import parse_components  # noqa: E402


def _components(graph: Graph, spec: ContainerSpec) -> list[dict]:
    cmd = graph.command(spec)
    assert Path(cmd[0]).name == "component_container" and cmd[1] == "--components"
    return json.loads(cmd[2])


def test_a_fleet_runs_one_container_per_ego_and_every_node_keeps_its_arguments():
    methods = ["bezier", "blind", "reserve"]
    per_node = fleet_graph(methods, scene=True, processes="node")
    per_ego = fleet_graph(methods, scene=True)  # the default
    assert [n.key for n in per_ego] == ["avp_sim", "ego0.pipeline", "ego1.pipeline", "ego2.pipeline", "avp_v2v",
                                        "avp_reservation"]
    graph = Graph(per_ego, Path("/tmp"))
    by_key = {n.key: n for n in per_node}
    for i in range(3):
        box = per_ego[1 + i]
        assert box.member_keys == [f"ego{i}.avp_belief", f"ego{i}.avp_prediction", f"ego{i}.avp_planner",
                                   f"ego{i}.avp_scene"]
        # each component is built with exactly the ROS arguments its own process would get, after --ros-args
        for comp, key in zip(_components(graph, box), box.member_keys, strict=True):
            own = Graph(per_node, Path("/tmp")).command(by_key[key])
            assert comp["args"] == own[own.index("--ros-args") + 1:]
            assert comp["component"].split(":")[0].split(".")[0] == by_key[key].package
    # the node-level differences survive: ego 1's predictor is blind's, ego 2 reads the reservation's observation
    ego1 = _components(graph, per_ego[2])
    ego0 = _components(graph, per_ego[1])
    assert ego1[1]["args"] != ego0[1]["args"]  # blind's prediction node differs from bezier's
    ego2 = _components(graph, per_ego[3])
    assert all("observation:=reserved/observation" in c["args"] for c in ego2)
    assert not any("observation:=reserved/observation" in c["args"] for c in ego0)
    # the simulator, the V2V node and the book keep their own processes, with the same arguments
    for key in ("avp_sim", "avp_v2v", "avp_reservation"):
        assert graph.command(next(n for n in per_ego if n.key == key)) == graph.command(by_key[key])


def test_a_string_parameter_that_reads_as_a_number_stays_a_string():
    """The reservation book of one `reserve` ego (ego 1) gets ``egos:='1'``: unquoted, ROS reads ``1`` as an integer
    and the node refuses to start ("parameter 'egos': expected a string")."""
    nodes = fleet_graph(["bezier", "reserve"])
    book = next(n for n in nodes if n.key == "avp_reservation")
    cmd = Graph(nodes, Path("/tmp")).command(book)
    assert "egos:='1'" in cmd and "lockstep:=true" in cmd
    v2v = Graph(nodes, Path("/tmp")).command(next(n for n in nodes if n.key == "avp_v2v"))
    assert "egos:=0,1" in v2v


def test_one_ego_and_the_node_layout_are_left_as_they_are():
    one = fleet_graph(["bezier"])
    assert [n.key for n in one] == ["avp_sim", "avp_belief", "avp_prediction", "avp_planner"]
    assert one_process_per_ego(one) == one  # nothing in an ego namespace
    nodes = fleet_graph(["bezier", "bezier"], processes="node")
    assert layout(nodes, "node") == nodes
    assert not any(isinstance(n, ContainerSpec) for n in nodes)


@pytest.mark.parametrize("bad", ["threads", "", "EGO"])
def test_an_unknown_process_layout_is_one_clear_error(bad):
    with pytest.raises(ValueError, match="--processes: expected one of ego, node"):
        fleet_graph(["bezier", "bezier"], processes=bad)
    with pytest.raises(ValueError, match="--processes"):
        fleet_graph(["bezier"], processes=bad)  # also where one ego leaves nothing to lay out


@pytest.mark.parametrize(("text", "match"), [
    ("not json", r"--components: not JSON"),
    ("[]", r"non-empty list"),
    ('{"component": "a:B"}', r"non-empty list"),
    ('[{"component": "avp_x.y:Z"}]', r"--components\[0\]: expected"),
    ('[{"component": "avp_x.y:Z", "args": [1]}]', r"--components\[0\]: expected"),
])
def test_bad_components_are_named(text, match):
    with pytest.raises(ValueError, match=match):
        parse_components(text)


@pytest.mark.parametrize(("components", "match"), [
    ('[{"component": "os.path:join", "args": []}]', "expected 'avp_<package>.<module>:<Class>'"),
    ('[{"component": "avp_perception.belief_node", "args": []}]', "expected 'avp_<package>.<module>:<Class>'"),
    ('[{"component": "avp_perception.no_such_module:X", "args": []}]', "no_such_module"),
    ('[{"component": "avp_perception.belief_node:NoSuchNode", "args": []}]', "NoSuchNode"),
])
def test_the_container_refuses_what_it_cannot_load_in_one_line(components, match, capsys):
    assert container_main(["--components", components]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("[component_container] start-up failed:") and match in err[0], err


def test_a_planners_shutdown_unloads_it_and_its_container_lives_on(ros_env, tmp_path, monkeypatch):
    """Over DDS: ego 0's container (belief, prediction, planner) puts its three nodes in /avp/ego0; the planner's
    lifecycle shutdown (what `avp swap-planner` sends the old planner) takes it out of the ROS graph while the process
    and the two other nodes stay; SIGINT then ends the container with 0."""
    import signal
    import time

    import rclpy
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    box = fleet_graph(["bezier", "bezier"])[1]
    graph = Graph([box], tmp_path / "logs", env=ros_env)
    rclpy.init()
    probe = rclpy.create_node("probe")

    def names() -> set[str]:
        return {n for n, ns in probe.get_node_names_and_namespaces() if ns == "/avp/ego0"}

    graph.start()
    try:
        t0 = time.monotonic()
        while names() != {"avp_belief", "avp_prediction", "avp_planner"} and time.monotonic() - t0 < 120:
            rclpy.spin_once(probe, timeout_sec=0.2)
        assert names() == {"avp_belief", "avp_prediction", "avp_planner"}, graph.log_tail("ego0.pipeline")
        client = probe.create_client(ChangeState, "/avp/ego0/avp_planner/change_state")
        assert client.wait_for_service(timeout_sec=60)
        future = client.call_async(ChangeState.Request(transition=Transition(id=Transition.TRANSITION_ACTIVE_SHUTDOWN)))
        rclpy.spin_until_future_complete(probe, future, timeout_sec=60)
        assert future.result() is not None and future.result().success
        t0 = time.monotonic()
        while "avp_planner" in names() and time.monotonic() - t0 < 60:
            rclpy.spin_once(probe, timeout_sec=0.2)
        assert names() == {"avp_belief", "avp_prediction"}, names()
        assert graph.poll() == {"ego0.pipeline": None}
        assert "unloaded from its component container" in graph.log_tail("ego0.pipeline")
        graph.kill_node("ego0.pipeline", signal.SIGINT)
        assert graph.procs["ego0.pipeline"].wait(60) == 0, graph.log_tail("ego0.pipeline")
        assert "Traceback" not in (tmp_path / "logs" / "ego0.pipeline.log").read_text()
    finally:
        graph.stop()
        probe.destroy_node()
        rclpy.try_shutdown()

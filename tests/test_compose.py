"""One process per ego (avp_bringup.compose, avp_bringup.container): which nodes share a component container, that
each keeps the ROS arguments of its own process, and the container's one-line errors. Over DDS:
tests/test_fleet_dds.py (K = 2 in containers equal to in-process; one ego's planner swapped out of its container)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("rclpy")

from avp_bringup.compose import ContainerSpec, layout, one_process_per_ego  # noqa: E402
from avp_bringup.container import main as container_main  # noqa: E402
from avp_bringup.container import parse_components  # noqa: E402
from avp_bringup.graph import Graph, fleet_graph  # noqa: E402


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

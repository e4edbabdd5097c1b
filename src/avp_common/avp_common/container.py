"""A component container: several of the graph's nodes in one process, on one executor (ROS 2 composition).

``install/avp_common/lib/avp_common/component_container --components JSON``, JSON a list of
``{"component": "package.module:Class", "args": [ROS arguments]}``: each entry is built as
``Class(cli_args=["--ros-args", *args], use_global_arguments=False)``, so every node keeps its own name, namespace,
remappings and parameter files exactly as it would have in a process of its own
(:meth:`avp_bringup.graph.Graph.command` builds both). The nodes share one
:class:`rclpy.executors.SingleThreadedExecutor`; they still talk over DDS (rclpy has no intra-process transport), but
build one message per payload they all receive (:func:`avp_common.received.share_received`), and a fleet's ego
pipeline is one process instead of three or four (docs/architecture.md, "Processes").

A node that ends itself (the planner's lifecycle *shutdown*, :attr:`avp_planner.planner_node.PlannerNode.end_hook`)
is unloaded and destroyed; the others keep running, and the container exits when none is left. A component that
fails to build (a bad parameter) prints one line naming it and the container exits with 2, as a node's own process
does (:func:`avp_common.node_main.run_node`). The components are named by the launcher (``avp launch``,
``avp demo``), never by a message on the domain.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
from dataclasses import dataclass

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

from avp_common.lifetime import end_with_starter
from avp_common.node_main import ctrl_c_in_finaliser_hook, freeze_start_up_heap, install_stop_handlers, stopping
from avp_common.params import ParameterError
from avp_common.received import share_received


@dataclass(frozen=True)
class Component:
    """One node of a container: its class (``package.module:Class``) and its ROS arguments."""

    component: str
    args: tuple[str, ...]

    def load(self) -> type:
        module, _, cls = self.component.partition(":")
        if not module.startswith("avp_") or not cls:
            raise ValueError(f"component '{self.component}': expected 'avp_<package>.<module>:<Class>'")
        return getattr(importlib.import_module(module), cls)


def parse_components(text: str) -> list[Component]:
    """The ``--components`` JSON; ValueError naming what is wrong with it."""
    try:
        items = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"--components: not JSON ({exc})") from exc
    if not isinstance(items, list) or not items:
        raise ValueError("--components: expected a non-empty list of {component, args}")
    out = []
    for i, item in enumerate(items):
        if not (isinstance(item, dict) and isinstance(item.get("component"), str)
                and isinstance(item.get("args"), list) and all(isinstance(a, str) for a in item["args"])):
            raise ValueError(f"--components[{i}]: expected {{'component': 'module:Class', 'args': [str, ...]}}")
        out.append(Component(item["component"], tuple(item["args"])))
    return out


def _unload(node) -> None:
    """Destroy ``node`` so that it leaves the ROS graph while the process lives on. rclpy's LifecycleNode has no
    ``destroy_node`` of its own: its state machine keeps the node's handle, and with it the node in the graph, until
    the state machine is destroyed too."""
    node.get_logger().info("unloaded from its component container")
    node.destroy_node()
    state_machine = getattr(node, "_state_machine", None)
    if state_machine is not None:
        state_machine.destroy_when_not_in_use()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="component_container", description=__doc__.split("\n\n")[0])
    ap.add_argument("--components", required=True, help="JSON list of {component, args}")
    args, _ = ap.parse_known_args(argv)
    try:
        components = parse_components(args.components)
        classes = [c.load() for c in components]
    except (ValueError, ImportError, AttributeError) as exc:
        print(f"[component_container] start-up failed: {exc}", file=sys.stderr)
        return 2
    install_stop_handlers()
    end_with_starter()  # SIGTERM when the graph's launcher ends, however it ended (avp_common.lifetime)
    share_received()  # the nodes of one process share what they receive (avp_common.received)
    rclpy.init(args=[])
    hook, sys.unraisablehook = sys.unraisablehook, ctrl_c_in_finaliser_hook
    executor = SingleThreadedExecutor()
    nodes: list = []
    ending: set[int] = set()
    try:
        for comp, cls in zip(components, classes, strict=True):
            try:
                node = cls(cli_args=["--ros-args", *comp.args], use_global_arguments=False)
            except (ParameterError, ValueError) as exc:
                print(f"[component_container] start-up failed: {comp.component}: {exc}", file=sys.stderr)
                return 2
            if hasattr(node, "end_hook"):  # a node that ends itself is unloaded, not the process
                node.end_hook = lambda n=node: ending.add(id(n))
            nodes.append(node)
            executor.add_node(node)
        freeze_start_up_heap()  # what the nodes built is no work for the garbage collector (avp_common.node_main)
        while nodes and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
            for node in [n for n in nodes if id(n) in ending]:
                executor.remove_node(node)
                nodes.remove(node)
                _unload(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if rclpy.ok() and not stopping():  # as run_node: an error after SIGINT/SIGTERM is part of the stop
            raise
    finally:
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown()
        sys.unraisablehook = hook
    return 0


if __name__ == "__main__":
    sys.exit(main())

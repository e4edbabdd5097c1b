"""Which of the graph's nodes share a process: one per node, or one per ego (a component container each).

ROS 2 composition: several nodes in one process on one executor (avp_common.container). A fleet's ego pipeline —
belief node, prediction node, planner, and its scene node when drawn — is one chain that runs one step at a time, so
running it in one process loses no parallelism and saves two or three Python processes per ego: with K = 2 on two
cores the live graph has 6 processes instead of 10 (docs/benchmarks.md, "The live fleet in one process per ego").
The simulator, the V2V node and the reservation book keep their own processes; so does every node of a one-ego
graph.
"""

from __future__ import annotations

import argparse
import json
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: an ego's namespace (avp_bringup.graph.ego_namespace: ``/avp/ego<i>``)
_EGO_NAMESPACE = re.compile(r"/ego\d+$")

#: how the graph's nodes are spread over processes (``--processes``)
PROCESS_LAYOUTS = ("ego", "node")


@dataclass(frozen=True)
class ContainerSpec:
    """A component container holding ``members`` (:class:`avp_bringup.graph.NodeSpec` each, with its ``component``
    class), named like its nodes with ``name`` for theirs in :attr:`avp_bringup.graph.Graph.procs` and the log
    directory (``ego0.pipeline`` for ``ego0.avp_belief``, ...)."""

    name: str
    members: tuple[Any, ...]

    @property
    def namespace(self) -> str:
        return self.members[0].namespace

    @property
    def key(self) -> str:
        head, _, _ = self.members[0].key.rpartition(".")
        return f"{head}.{self.name}" if head else self.name

    @property
    def member_keys(self) -> list[str]:
        return [m.key for m in self.members]

    def command(self, ros_args: Callable[[Any], list[str]]) -> list[str]:
        from ament_index_python.packages import get_package_prefix

        exe = Path(get_package_prefix("avp_common")) / "lib" / "avp_common" / "component_container"
        components = [{"component": m.component, "args": ros_args(m)} for m in self.members]
        return [str(exe), "--components", json.dumps(components)]


def one_process_per_ego(nodes: list) -> list:
    """``nodes`` with the nodes of each ego namespace (``/avp/ego<i>``) that have a ``component`` gathered into one
    :class:`ContainerSpec` (``ego<i>.pipeline``), placed where its first node was; every other node as it was."""
    groups: dict[str, list] = {}
    for n in nodes:
        if n.component and _EGO_NAMESPACE.search(n.namespace):
            groups.setdefault(n.namespace, []).append(n)
    out: list = []
    for n in nodes:
        members = groups.get(n.namespace) if n.component else None
        if not members:
            out.append(n)
        elif n is members[0]:
            out.append(ContainerSpec("pipeline", tuple(members)))
    return out


def layout(nodes: list, processes: str) -> list:
    """``nodes`` laid out over processes: ``"node"`` one each, ``"ego"`` :func:`one_process_per_ego`. ValueError
    for another word."""
    if processes not in PROCESS_LAYOUTS:
        raise ValueError(f"--processes: expected one of {', '.join(PROCESS_LAYOUTS)}, got '{processes}'")
    return one_process_per_ego(nodes) if processes == "ego" else list(nodes)


def add_processes_argument(p: argparse.ArgumentParser) -> None:
    """``--processes {ego,node}`` of ``avp launch`` and ``avp demo`` (only a fleet's graph is laid out)."""
    p.add_argument("--processes", choices=PROCESS_LAYOUTS, default="ego",
                   help="with --egos K > 1: one process per ego pipeline (a component container: belief, prediction, "
                   "planner and scene nodes; the default) or one per node")

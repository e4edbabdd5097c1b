"""Start and stop the AVP node graph as separate processes (ros2 launch is not on PyPI, docs/install.md).

Each node runs as ``install/<pkg>/lib/<pkg>/<exe> --ros-args -r __ns:=/avp --params-file <default>
[--params-file <user>]``; its stdout/stderr go to ``<log_dir>/<node>.log``.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

from ament_index_python.packages import get_package_prefix, get_package_share_directory

NAMESPACE = "/avp"


@dataclass(frozen=True)
class NodeSpec:
    name: str
    package: str
    executable: str
    param_file: str  # relative to the package's share directory
    extra_params: dict = field(default_factory=dict)

    def executable_path(self) -> Path:
        return Path(get_package_prefix(self.package)) / "lib" / self.package / self.executable

    def default_params(self) -> Path:
        return Path(get_package_share_directory(self.package)) / self.param_file


EGO_NODES = {
    "planner": NodeSpec("avp_planner", "avp_planner", "planner", "config/planner.param.yaml"),
    "scripted": NodeSpec("scripted_driver", "avp_planner", "scripted_driver", "config/scripted_driver.param.yaml"),
}


def default_graph(ego: str = "planner") -> list[NodeSpec]:
    """The live graph: simulator + the ego's Hybrid A* planner (§V-D) — or the scripted stand-in driver.

    Until the perception nodes (#4) land, the planner runs with beliefs from observation only and no
    predictions (its `use_beliefs` / `use_predictions` parameters are false).
    """
    return [NodeSpec("avp_sim", "avp_sim", "sim_node", "config/sim.param.yaml"), EGO_NODES[ego]]


def _ros_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return v if v else "''"
    return repr(v)


class Graph:
    """A running set of node processes."""

    def __init__(self, nodes: list[NodeSpec], log_dir: Path, user_params: str | None = None,
                 env: dict | None = None):
        self.nodes = nodes
        self.log_dir = Path(log_dir)
        self.user_params = user_params
        self.env = dict(os.environ if env is None else env)
        self.procs: dict[str, subprocess.Popen] = {}

    def command(self, spec: NodeSpec) -> list[str]:
        cmd = [str(spec.executable_path()), "--ros-args", "-r", f"__ns:={NAMESPACE}", "-r", f"__node:={spec.name}",
               "--params-file", str(spec.default_params())]
        if self.user_params:
            cmd += ["--params-file", str(Path(self.user_params).resolve())]
        for k, v in spec.extra_params.items():
            cmd += ["-p", f"{k}:={_ros_value(v)}"]
        return cmd

    def start(self) -> None:
        self.log_dir.mkdir(parents=True, exist_ok=True)
        for spec in self.nodes:
            self.start_node(spec)

    def start_node(self, spec: NodeSpec) -> subprocess.Popen:
        log = open(self.log_dir / f"{spec.name}.log", "ab")  # noqa: SIM115 - owned by the process
        proc = subprocess.Popen(self.command(spec), stdout=log, stderr=subprocess.STDOUT, env=self.env,
                                start_new_session=True)
        self.procs[spec.name] = proc
        return proc

    def poll(self) -> dict[str, int | None]:
        return {name: p.poll() for name, p in self.procs.items()}

    def kill_node(self, name: str, sig: int = signal.SIGKILL) -> None:
        self.procs[name].send_signal(sig)

    def stop(self, timeout: float = 5.0) -> None:
        for p in self.procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        deadline = time.monotonic() + timeout
        for p in self.procs.values():
            try:
                p.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()

    def __enter__(self) -> Graph:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

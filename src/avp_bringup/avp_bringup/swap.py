"""Live planner swap (`avp swap-planner`), on the lifecycle calls of :mod:`avp_bringup.lifecycle`.

A *planner* is any node publishing on ``<namespace>/cmd``; to be swappable it must be a lifecycle
(managed) node (lifecycle_msgs services ``<node>/get_state`` and ``<node>/change_state``). A swap

1. (for a profile) starts ``avp_planner/planner`` as a new process with the profile's parameter file and
   ``autostart:=false``, detached from the swap command and tied to the graph's launcher (it ends when the
   launcher ends, :func:`graph_lifetime_env`), and waits for its lifecycle services; it inherits the running planner's
   inputs (``use_beliefs``, ``use_predictions``, ``use_ego_intention``, ``use_beacons``: e.g. the spot order of
   ``avp launch --method implicit``) and the topic it reads its observation from (a ``reserve`` ego's planner reads
   the reservation node's ``reserved/observation``, the held spots shown as occupied), so that the swap keeps the
   graph's method and its coordination;
2. configures the new planner (it builds its core for the lot; still silent);
3. deactivates every other active planner — from here until step 4 no command is published: in
   lock-step the simulator waits, in real time its watchdog holds the ego still;
4. activates the new planner (it answers the newest observation first);
5. shuts the old planners down (their processes exit; a planner in a fleet's component container is unloaded from
   it and its ego's other nodes run on, avp_common.container), unless asked to keep them.

Docs: docs/custom_planner.md (the topic contract and a minimal planner of your own).
"""

from __future__ import annotations

import re
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

from avp_bringup.lifecycle import LifecycleClient, SwapError, fq_name

__all__ = ["SwapError", "SwapReport", "WIRING", "available_profiles", "profiles_dir", "resolve_profile",
           "start_planner_process", "swap_planner", "unique_name", "validate_profile"]


def profiles_dir() -> Path:
    from ament_index_python.packages import get_package_share_directory

    return Path(get_package_share_directory("avp_planner")) / "config" / "profiles"


def available_profiles() -> list[str]:
    d = profiles_dir()
    return sorted(p.stem for p in d.glob("*.yaml")) if d.is_dir() else []


def resolve_profile(profile: str) -> Path:
    """A profile name (``config/profiles/<name>.yaml`` of avp_planner) or a path to a parameter YAML."""
    p = Path(profile)
    if p.suffix in (".yaml", ".yml") or "/" in profile:
        if not p.is_file():
            raise SwapError(f"profile file {p} does not exist")
        return p.resolve()
    f = profiles_dir() / f"{profile}.yaml"
    if not f.is_file():
        raise SwapError(f"unknown planner profile '{profile}'; available: {available_profiles()} "
                        f"(or give a parameter YAML path)")
    return f


def validate_profile(path: Path) -> None:
    """Check the profile's keys/types/ranges like the node will (one line naming file and key)."""
    import yaml

    from avp_common.params import ParameterError, check_value
    from avp_planner.params import PLANNER_PARAMS

    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise SwapError(f"{path}: cannot read profile ({exc})") from None
    block = (data or {}).get("/**", {}) if isinstance(data, dict) else None
    params = block.get("ros__parameters") if isinstance(block, dict) else None
    if not isinstance(params, dict):
        raise SwapError(f"{path}: a profile is a ROS 2 parameter file: '/**: ros__parameters: {{...}}'")
    from avp_common.params import _flatten

    specs = {s.name: s for s in PLANNER_PARAMS}
    for key, value in _flatten(params).items():
        if key not in specs:
            raise SwapError(f"{path}: parameter '{key}': unknown key")
        try:
            check_value(specs[key], value, str(path))
        except ParameterError as exc:
            raise SwapError(str(exc)) from None


@dataclass
class SwapReport:
    new: str
    pid: int | None = None
    log: Path | None = None
    deactivated: list[str] = field(default_factory=list)
    shut_down: list[str] = field(default_factory=list)
    gap_s: float = 0.0  # wall time with no active planner
    observation: str = ""  # the topic a planner started from a profile reads its observation from


#: the planner's inputs, inherited by a swapped-in planner from the running one
WIRING = ("use_beliefs", "use_predictions", "use_ego_intention", "use_beacons")


def default_observation(namespace: str) -> str:
    """The observation topic a planner in ``namespace`` reads unless remapped (the simulator's)."""
    return f"{namespace.rstrip('/')}/observation"


def start_planner_process(name: str, profile: Path, namespace: str, log_dir: Path, user_params: str | None,
                          env: dict | None = None, wiring: dict | None = None,
                          observation: str | None = None) -> tuple[subprocess.Popen, Path]:
    """``avp_planner/planner`` as a detached process named ``name`` (unconfigured: autostart false), with
    the parameters the default graph gives its planner (use_beliefs / use_predictions), replaced by ``wiring``
    (the running planner's inputs, :data:`WIRING`) where given; ``observation``: the running planner's observation
    topic (fully qualified), read instead of ``<namespace>/observation`` when it differs."""
    from avp_bringup.graph import EGO_REMAPS, Graph, NodeSpec, default_graph
    from avp_common.msg_auth import ego_scope

    base = next(s for s in default_graph("planner") if s.package == "avp_planner" and s.executable == "planner")
    extra = {**base.extra_params, **{k: v for k, v in (wiring or {}).items() if k in WIRING}, "autostart": False}
    # in an ego's namespace (avp launch --egos K) it reads the lot's lot_map, as that ego's pipeline does
    remaps = EGO_REMAPS if ego_scope(namespace) else ()
    if observation and observation != default_observation(namespace):
        remaps += (("observation", observation),)
    spec = NodeSpec(name, base.package, base.executable, base.param_file, extra, namespace=namespace, remaps=remaps)
    cmd = Graph([spec], log_dir, user_params).command(spec)
    cmd[cmd.index("-p"):cmd.index("-p")] = ["--params-file", str(profile)]  # defaults < user < profile < -p
    log_dir.mkdir(parents=True, exist_ok=True)
    log = log_dir / f"{spec.key}.log"
    with open(log, "ab") as f:
        proc = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, env=graph_lifetime_env(env),
                                start_new_session=True)
    return proc, log


def graph_lifetime_env(env: dict | None = None) -> dict:
    """The environment of a swapped-in planner: it ends with the launcher of the graph it joins (the domain's
    launcher file, avp_bringup.launcher_file), never with the swap command; with no launcher recorded (a graph
    started by other means) it lives on until it is shut down, as a detached process."""
    from avp_bringup.launcher_file import read_launcher
    from avp_common.lifetime import tie_env, untie_env

    launcher = read_launcher(env)
    return tie_env(env, pid=launcher) if launcher is not None else untie_env(env)


def unique_name(client: LifecycleClient, namespace: str, base: str) -> str:
    taken = {n.split("/")[-1] for n in client.lifecycle_nodes(namespace)} | {
        n for n, ns in client.node.get_node_names_and_namespaces() if ns.rstrip("/") == namespace.rstrip("/")}
    name, i = base, 2
    while name in taken:
        name, i = f"{base}_{i}", i + 1
    return name


def swap_planner(client: LifecycleClient, namespace: str, *, profile: str | None = None, node: str | None = None,
                 name: str | None = None, log_dir: Path | None = None, user_params: str | None = None,
                 keep_old: bool = False, timeout: float = 30.0, env: dict | None = None,
                 discovery: float = 3.0) -> SwapReport:
    """Bring up ``profile`` (a new planner process) or the running lifecycle node ``node`` in place of the
    active planner(s); see the module docstring."""
    if (profile is None) == (node is None):
        raise SwapError("give a profile or --node, not both")
    path = None
    if profile is not None:
        path = resolve_profile(profile)
        validate_profile(path)
    client.spin(0.5)  # graph discovery (continued below while the new planner starts)
    report = SwapReport(new=node or "")
    proc = None
    if path is not None:
        base = name or "avp_planner_" + re.sub(r"[^A-Za-z0-9_]", "_", path.stem)
        new_name = unique_name(client, namespace, base)
        log_dir = log_dir or Path.cwd() / "out" / "logs" / time.strftime("swap-%Y%m%d-%H%M%S")
        wiring: dict = {}
        observation = None
        # the running planner(s), waited for: a fresh process on a loaded machine may not yet have discovered them,
        # and a swap that found none would start the new planner with the default inputs instead of theirs
        # (module docstring, step 1: keep the graph's method)
        for running in client.planners(namespace, wait=min(timeout, 10.0)):
            wiring = client.parameters(running, WIRING, timeout=min(timeout, 5.0))
            observation = client.observation_topic(running, wait=min(timeout, 10.0))
            if wiring:
                break
        proc, log = start_planner_process(new_name, path, namespace, log_dir, user_params, env, wiring, observation)
        report.new, report.pid, report.log = fq_name(namespace, new_name), proc.pid, log
        report.observation = observation or default_observation(namespace)
        t0 = time.monotonic()
        while not client.is_lifecycle(report.new):
            if proc.poll() is not None:
                raise SwapError(f"{report.new} exited at start-up (code {proc.returncode}); see {log}")
            if time.monotonic() - t0 > timeout:
                proc.kill()
                raise SwapError(f"{report.new} did not come up within {timeout} s; see {log}")
            client.spin(0.1)
    elif not client.is_lifecycle(node):
        client.spin(discovery)
        if not client.is_lifecycle(node):
            raise SwapError(f"{node}: no lifecycle services (is it running, in namespace {namespace}, "
                            f"a lifecycle node?)")
    target = report.new
    try:
        state = client.state(target, timeout)
        if state == "unconfigured":
            client.change(target, "configure", timeout)
        elif state not in ("inactive", "active"):
            raise SwapError(f"{target}: cannot bring it up from state '{state}'")
        # the planners to replace: every other publisher on cmd
        others = client.planners(namespace, wait=discovery, exclude=target)
        unmanaged = [n for n in others if not client.is_lifecycle(n)]
        if unmanaged:
            raise SwapError(f"{unmanaged} publish {namespace}/cmd but are not lifecycle nodes: stop them first "
                            f"(e.g. the scripted driver) or run a lifecycle planner")
    except SwapError:
        if proc is not None:  # do not leave the new planner behind
            proc.terminate()
        raise
    states = {n: client.state(n, timeout) for n in others}
    t_gap = time.monotonic()
    for n in others:
        if states[n] == "active":
            client.change(n, "deactivate", timeout)
            report.deactivated.append(n)
    if client.state(target, timeout) != "active":
        client.change(target, "activate", timeout)
    report.gap_s = time.monotonic() - t_gap
    if not keep_old:
        for n in others:
            client.change(n, "shutdown", timeout)
            report.shut_down.append(n)
    return report

"""Start and stop the AVP node graph as separate processes (ros2 launch is not on PyPI, docs/install.md).

Each node runs as ``install/<pkg>/lib/<pkg>/<exe> --ros-args -r __ns:=/avp --params-file <default>
[--params-file <user>]``; its stdout/stderr go to ``<log_dir>/<node>.log``. With K egos (:func:`fleet_graph`) ego
i's pipeline runs in ``/avp/ego<i>`` and logs to ``<log_dir>/ego<i>.<node>.log``.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

NAMESPACE = "/avp"


@dataclass(frozen=True)
class NodeSpec:
    name: str
    package: str
    executable: str
    param_file: str  # relative to the package's share directory
    extra_params: dict = field(default_factory=dict)
    namespace: str = NAMESPACE
    remaps: tuple[tuple[str, str], ...] = ()  # (from, to) name remappings
    component: str = ""  # its node class, ``module:Class``, for a component container (avp_bringup.compose)

    @property
    def key(self) -> str:
        """The node's name in :attr:`Graph.procs` and its log file's stem: ``ego1.avp_planner`` in /avp/ego1."""
        sub = self.namespace[len(NAMESPACE):].strip("/") if self.namespace.startswith(NAMESPACE) else self.namespace
        return f"{sub.replace('/', '.')}.{self.name}" if sub else self.name

    def executable_path(self) -> Path:
        from ament_index_python.packages import get_package_prefix  # a graph needs the sourced workspace

        return Path(get_package_prefix(self.package)) / "lib" / self.package / self.executable

    def default_params(self) -> Path:
        from ament_index_python.packages import get_package_share_directory

        return Path(get_package_share_directory(self.package)) / self.param_file


EGO_NODES = {
    "planner": NodeSpec("avp_planner", "avp_planner", "planner", "config/planner.param.yaml",
                        component="avp_planner.planner_node:PlannerNode"),
    "scripted": NodeSpec("scripted_driver", "avp_planner", "scripted_driver", "config/scripted_driver.param.yaml"),
}


PERCEPTION_NODES = [
    NodeSpec("avp_belief", "avp_perception", "belief_node", "config/belief.param.yaml",
             component="avp_perception.belief_node:BeliefNode"),
    NodeSpec("avp_prediction", "avp_perception", "prediction_node", "config/prediction.param.yaml",
             component="avp_perception.prediction_node:PredictionNode"),
]
#: what the planner is told in the full graph: wait for the perception nodes' beliefs and predictions
PLANNER_WITH_PERCEPTION = {"use_beliefs": True, "use_predictions": True}


def default_graph(ego: str = "planner") -> list[NodeSpec]:
    """The live graph, the simulator first and the ego's node last.

    ``planner``: simulator, belief node (eq. 7, intent CNN, eq. 8), prediction node (§V-C), Hybrid A* planner
    (§V-D) with ``use_beliefs`` / ``use_predictions`` true, i.e. in lock-step it answers observation k once the
    beliefs and predictions stamped t_k have arrived. ``scripted``: simulator + the scripted stand-in driver.
    The simulator's step 0 waits until every node that subscribes to observation (all but itself) is there.
    """
    if ego == "planner":
        ego_spec = EGO_NODES["planner"]
        nodes = [*PERCEPTION_NODES, with_params(ego_spec, **PLANNER_WITH_PERCEPTION)]
    else:
        nodes = [EGO_NODES[ego]]
    sim = NodeSpec("avp_sim", "avp_sim", "sim_node", "config/sim.param.yaml", {"min_subscribers": len(nodes)})
    return [sim, *nodes]


#: the viewers' node: /tf, /tf_static and viz/scene from the pipeline's messages; a sink, never an input
SCENE_NODE = NodeSpec("avp_scene", "avp_viz", "scene_node", "config/scene.param.yaml",
                      component="avp_viz.scene_node:SceneNode")
#: the spot-reservation book of a fleet with `reserve` egos (docs/world.md, "The spot-reservation reference")
RESERVATION_NODE = NodeSpec("avp_reservation", "avp_planner", "reservation", "config/reservation.param.yaml")
#: the radio between a fleet's egos: each planner hears the beacons of the egos before it (decision.ego_yield)
V2V_NODE = NodeSpec("avp_v2v", "avp_planner", "v2v", "config/v2v.param.yaml")


def with_scene(nodes: list[NodeSpec]) -> list[NodeSpec]:
    """``nodes`` (a graph whose first node is the simulator) plus :data:`SCENE_NODE`; the simulator's step 0 also
    waits for it (it subscribes to observation), so the scene and transforms of every step are published."""
    sim = nodes[0]
    n = sim.extra_params.get("min_subscribers", len(nodes) - 1)
    return [with_params(sim, min_subscribers=n + 1), *nodes[1:], SCENE_NODE]


#: the tracker between the simulator's noisy sensing and the ego's nodes (avp_tracking; docs/perception.md)
TRACKER_NODE = NodeSpec("avp_tracker", "avp_tracking", "tracker_node", "config/tracker.param.yaml",
                        component="avp_tracking.tracker_node:TrackerNode")
SENSING_MODELS = ("exact", "realistic", "harsh", "custom")


def add_sensing_arguments(p) -> None:
    """``--sensing`` and ``--detections`` of `avp launch` and `avp demo` (an argparse parser ``p``)."""
    p.add_argument("--sensing", default="exact", choices=SENSING_MODELS,
                   help="the simulator's sensing model (sensing.model): exact (the paper) or noisy detections "
                   "through the tracker node avp_tracker (docs/perception.md)")
    p.add_argument("--detections", metavar="TOPIC", help="the tracker reads a real detector's "
                   "autoware_perception_msgs/DetectedObjects from TOPIC instead of the simulator's (untagged, on its "
                   "own clock); needs --sensing other than exact (docs/perception.md, 'A real detector')")


def with_sensing(nodes: list[NodeSpec], model: str, detections: str | None = None) -> list[NodeSpec]:
    """``nodes`` (a one-ego graph, the simulator first) with the sensing model ``model``: for any model but exact,
    the simulator publishes its frame and detections to :data:`TRACKER_NODE`, inserted after it, whose observation
    the ego's nodes read; the tracker holds its first answer for the subscribers the simulator's step 0 waited for,
    and the simulator waits for the tracker. ``exact``: ``nodes`` unchanged (the paper). ``detections``: the topic of
    a real detector's DetectedObjects, read instead of the simulator's (untagged, on its own clock: ``sync:
    latest``; docs/perception.md, "A real detector")."""
    if model not in SENSING_MODELS:
        raise ValueError(f"--sensing: expected one of {SENSING_MODELS}, got {model!r}")
    if model == "exact":
        if detections:
            raise ValueError("--detections needs a sensing model other than exact (--sensing realistic, say)")
        return nodes
    sim = nodes[0]
    if sim.extra_params.get("egos.count", 1) > 1:
        raise ValueError(f"--sensing {model}: one ego only (the tracker serves one ego's sensing)")
    n = sim.extra_params.get("min_subscribers", len(nodes) - 1)
    tracker = with_params(TRACKER_NODE, min_subscribers=n, sync="stamp")
    if detections:
        tracker = replace(with_params(tracker, sync="latest", auth_detections=False),
                          remaps=(("sensing/detections", detections),))
    return [with_params(sim, **{"sensing.model": model, "min_subscribers": 1}), tracker, *nodes[1:]]


def with_params(spec: NodeSpec, **extra) -> NodeSpec:
    """``spec`` with ``extra`` parameters added to (or replacing) its ``extra_params``."""
    return replace(spec, extra_params={**spec.extra_params, **extra})


def ego_namespace(i: int) -> str:
    """Ego i's namespace among several egos: ``/avp/ego<i>``."""
    return f"{NAMESPACE}/ego{int(i)}"


#: what a pipeline in an ego's namespace reads from the lot's namespace
EGO_REMAPS = (("lot_map", f"{NAMESPACE}/lot_map"),)


def fleet_graph(methods: list, *, deterministic: bool = False, sim_extra: dict | None = None,
                scene: bool = False, intent_weights: str | None = None, intent_seed: int | None = None,
                processes: str = "ego") -> list:
    """The live graph of K = len(methods) egos (docs/world.md, "Several egos"): one simulator (``egos.count`` K)
    and, per ego i, the belief node, prediction node and planner of its method (:func:`method_graph`) in
    :func:`ego_namespace` (i), reading the lot's ``lot_map``, and the V2V node (:data:`V2V_NODE`) that gives each
    planner (``use_beacons``) the beacons of the egos before it. The simulator's step 0 waits for each ego's three
    observation subscribers (the reservation node's one for a ``reserve`` ego), the V2V node and its cmd publisher.
    ``scene``: a scene node per ego too (its frames
    ``ego<i>/`` on the one /tf, its colour; avp_viz.scene). One method gives the one-ego graph of
    :func:`method_graph`. ``intent_weights``, ``intent_seed``: as :func:`method_graph`'s, for every ego.
    ``processes``: ``"ego"`` (default) runs each ego's pipeline (and scene node) in one component container,
    ``"node"`` every node in a process of its own (avp_bringup.compose)."""
    from avp_bringup.compose import layout

    layout([], processes)  # an unknown layout: ValueError before anything is built
    intent = {"intent_weights": intent_weights, "intent_seed": intent_seed}
    if len(methods) == 1:
        return method_graph(methods[0], deterministic=deterministic, sim_extra=sim_extra, **intent)
    if not 1 <= len(methods) <= 8:
        raise ValueError(f"--egos: expected 1..8 automated cars, got {len(methods)}")
    nodes: list[NodeSpec] = []
    sim = None
    reserve = [i for i, m in enumerate(methods) if _coordination(m) == "reserve"]
    for i, m in enumerate(methods):
        sim_i, *pipeline = method_graph(m, deterministic=deterministic, coordinated=i in reserve, **intent)
        sim = sim or sim_i
        # a reserve ego's pipeline reads the observation the reservation node passes on (the held spots occupied)
        remaps = EGO_REMAPS + ((("observation", "reserved/observation"),) if i in reserve else ())
        # every planner hears the V2V node's beacons (decision.ego_yield)
        nodes += [replace(with_params(n, use_beacons=True) if n.executable == "planner" else n,
                          namespace=ego_namespace(i), remaps=remaps) for n in pipeline]
        if scene:
            nodes.append(replace(with_params(SCENE_NODE, ego_index=i), namespace=ego_namespace(i), remaps=remaps))
    assert sim is not None
    n_subs = sim.extra_params.get("min_subscribers", 3) + (1 if scene else 0)
    # the simulator waits for each pipeline's three nodes, or the book's one subscription, and the V2V node
    extra = {"egos.count": len(methods), "min_subscribers": (1 if reserve else n_subs) + 1, **(sim_extra or {})}
    sim = with_params(sim, **extra)
    lockstep = extra.get("mode", "lockstep") == "lockstep"
    # the V2V channel (avp_planner.v2v_node): it answers each observation with the beacons its ego hears
    nodes.append(with_params(V2V_NODE, egos=",".join(map(str, range(len(methods)))), lockstep=lockstep))
    if reserve:  # the spot-reservation book (avp_planner.reservation_node); it waits for their pipelines itself
        nodes.append(with_params(RESERVATION_NODE, egos=",".join(map(str, reserve)), min_subscribers=n_subs,
                                 lockstep=lockstep))
    return layout([sim, *nodes], processes)


def _coordination(method) -> str:
    from avp_episode.profiles import MethodProfile, load_profile

    return (method if isinstance(method, MethodProfile) else load_profile(method)).coordination


def method_graph(method, *, deterministic: bool = False, intent_weights: str | None = None,
                 intent_seed: int | None = None, sim_extra: dict | None = None, coordinated: bool = False
                 ) -> list[NodeSpec]:
    """The live graph of one Table I method: :func:`default_graph` ("planner") — the same four nodes
    — with the parameters of the method profile ``method`` (a name of avp_episode/config/methods/, a profile
    file or a :class:`~avp_episode.profiles.MethodProfile`) on its pipeline nodes
    (:func:`~avp_episode.profiles.method_node_params`, also for ``deterministic`` and the intent
    weights) and ``sim_extra`` on the simulator. ProfileError (a ValueError) for an unknown or unavailable
    method."""
    from avp_episode.profiles import MethodProfile, load_profile, method_node_params

    profile = method if isinstance(method, MethodProfile) else load_profile(method)
    params = method_node_params(profile, deterministic=deterministic, intent_weights=intent_weights,
                                intent_seed=intent_seed, coordinated=coordinated)
    nodes = [with_params(n, **params.get(n.name, {})) for n in default_graph("planner")]
    missing = set(params) - {n.name for n in nodes}
    assert not missing, f"method_node_params names nodes the graph does not have: {missing}"
    if sim_extra:
        nodes[0] = with_params(nodes[0], **sim_extra)
    return nodes


def ego_graph(method: str | None, ego: str = "planner", deterministic: bool = False) -> list[NodeSpec]:
    """The 4-node graph of a Table I ``method`` (its parameters on the belief node, the prediction node and the
    planner: :func:`method_graph`), or the simulator + scripted driver (``ego="scripted"``), or the default graph.
    ValueError when a method is given with the scripted ego."""
    if ego == "scripted":
        if method:
            raise ValueError("--method and --ego scripted exclude each other")
        return default_graph("scripted")
    return method_graph(method, deterministic=deterministic) if method else default_graph(ego)


def avp_root() -> Path:
    """Where ``out/`` and ``bags/`` go: $AVP_ROOT (set by tools/env.sh: the clone) or the working directory."""
    return Path(os.environ.get("AVP_ROOT", Path.cwd()))


def default_log_dir(arg: str | None = None) -> Path:
    """``arg`` if given, else out/logs/<time>/ under :func:`avp_root`."""
    return Path(arg) if arg else avp_root() / "out" / "logs" / time.strftime("%Y%m%d-%H%M%S")


def _ros_value(v) -> str:
    """``v`` as the value of ``-p name:=value``, which ROS reads as YAML: a string that YAML would read as something
    else (``1``, ``true``, ``1.5``, empty) is quoted, so a string parameter such as the reservation book's ``egos`` of
    one ego (``"1"``) stays a string."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        import yaml

        try:
            plain = isinstance(yaml.safe_load(v), str)
        except yaml.YAMLError:
            plain = False
        return v if v and plain else "'" + v.replace("'", "''") + "'"
    return repr(v)


#: Fast DDS XML profiles of the processes `avp` starts (heartbeat period of reliable writers).
FASTDDS_PROFILES = Path(__file__).resolve().parent / "dds" / "fastdds_profiles.xml"


class Graph:
    """A running set of node processes."""

    def __init__(self, nodes: list[NodeSpec], log_dir: Path, user_params: str | None = None,
                 env: dict | None = None):
        self.nodes = nodes
        self.log_dir = Path(log_dir)
        self.user_params = user_params
        self.env = dict(os.environ if env is None else env)
        # Fast DDS's shared-memory transport can block a publisher for seconds after a subscriber process was
        # SIGKILLed (its port is never drained): the graph's processes talk over UDPv4 loopback instead
        # (docs/architecture.md, "Faults"); FASTDDS_BUILTIN_TRANSPORTS=DEFAULT brings shared memory back.
        self.env.setdefault("FASTDDS_BUILTIN_TRANSPORTS", "UDPv4")
        # no other host reaches the graph unless the user widens discovery (ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET)
        self.env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        # reliable writers heartbeat every 50 ms instead of 3 s: a datagram lost on a loaded machine is repaired
        # within about a step instead of holding its stream back for seconds (dds/fastdds_profiles.xml)
        self.env.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", str(FASTDDS_PROFILES))
        self.procs: dict[str, subprocess.Popen] = {}

    def command(self, spec) -> list[str]:
        """The command line of ``spec``: a node's executable with its ROS arguments (:meth:`ros_args`), or a
        component container (:class:`avp_bringup.compose.ContainerSpec`) with those of each of its nodes."""
        if hasattr(spec, "members"):
            return spec.command(self.ros_args)
        return [str(spec.executable_path()), "--ros-args", *self.ros_args(spec)]

    def ros_args(self, spec: NodeSpec) -> list[str]:
        """What follows ``--ros-args`` for ``spec``: its namespace, name, remappings, the package's parameter file,
        the user's (``--params``) and its extra parameters, in that order (the later wins)."""
        cmd = ["-r", f"__ns:={spec.namespace}", "-r", f"__node:={spec.name}"]
        for src, dst in spec.remaps:
            cmd += ["-r", f"{src}:={dst}"]
        cmd += ["--params-file", str(spec.default_params())]
        if self.user_params:
            cmd += ["--params-file", str(Path(self.user_params).resolve())]
        for k, v in spec.extra_params.items():
            cmd += ["-p", f"{k}:={_ros_value(v)}"]
        return cmd

    def start(self) -> None:
        """Start every node; this process is recorded as the domain's launcher (avp_bringup.launcher_file), which
        a planner swapped in later ends with."""
        from avp_bringup.launcher_file import write_launcher

        self.log_dir.mkdir(parents=True, exist_ok=True)
        write_launcher(self.env)
        for spec in self.nodes:
            self.start_node(spec)

    def start_node(self, spec: NodeSpec) -> subprocess.Popen:
        """Start ``spec``'s process in a session of its own (a Ctrl-C in the launcher's terminal reaches the
        launcher alone, which stops the graph in order), tied to this process: it ends when this one ends, however
        this one ends (avp_common.lifetime; docs/architecture.md, "Processes")."""
        from avp_common.lifetime import tie_env

        log = open(self.log_dir / f"{spec.key}.log", "ab")  # noqa: SIM115 - owned by the process
        proc = subprocess.Popen(self.command(spec), stdout=log, stderr=subprocess.STDOUT, env=tie_env(self.env),
                                start_new_session=True)
        self.procs[spec.key] = proc
        return proc

    def poll(self) -> dict[str, int | None]:
        return {name: p.poll() for name, p in self.procs.items()}

    def log_tail(self, name: str, n_lines: int = 20) -> str:
        """The last ``n_lines`` lines of node ``name``'s log (for error messages)."""
        path = self.log_dir / f"{name}.log"
        if not path.is_file():
            return f"(no log {path})"
        return "\n".join(path.read_text(errors="replace").splitlines()[-n_lines:])

    def kill_node(self, name: str, sig: int = signal.SIGKILL) -> None:
        self.procs[name].send_signal(sig)

    def stop(self, timeout: float = 5.0) -> None:
        from avp_bringup.launcher_file import remove_launcher

        remove_launcher(self.env)
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

"""The ``avp`` command: run the live graph and its tools (ros2cli/launch are not on PyPI here).

  avp launch [--method NAME] [--params FILE] [--log-dir DIR] [--lot FILE] [--egos K] [--methods M1,M2,...]
             [--drivers N] [--foxglove]
                                                   start the node graph (a Table I method; K egos, one pipeline
                                                   each in /avp/ego<i>); Ctrl-C stops it
  avp demo   [--method NAME] [--seed N] [--non-reactive] [--realtime] [--out DIR] [--params FILE] [--lot FILE]
                                                   one seeded episode over DDS -> metrics.json (with the
                                                   closed-loop step time), episode.png, episode.gif
  avp record OUT [--topics T ...] [--storage mcap|sqlite3] [--split-period S]
                                                   record the graph to a rosbag2 until Ctrl-C (crash-safe splits)
  avp replay BAG [--rate R] [--start S] [--topics T ...]
                                                   republish a bag with its sim clock
  avp metrics BAG                                  recompute an episode's metrics from a bag
  avp teleop [--driver J] [--stamped]             drive car J of the running graph from the keyboard
  avp swap-planner PROFILE|--node NODE [--keep-old] [--ego I]
                                                   replace the running planner (lifecycle) while the sim steps
  avp experiment [--scenarios N] [--seed-base S] [--mode reactive|non-reactive|both] [--methods M,...|all]
                 [--workers W] [--out DIR] [--transport inproc|ros] [--lot FILE]
                                                   the Table I runner (docs/experiment.md); resumable
  avp bench sensing|planner|perception|soak|live_latency|learned|closed_loop [ARGS...]
                                                   run a benchmark script of bench/ (figures in docs/benchmarks.md)
  avp params [NODE]                                print the parameter tables (Markdown)
  avp train-intent [--scale full|quick|tiny] [--out DIR] [--workers W] [--threads T]
                                                   the intent CNN from scratch: data, training, evaluation,
                                                   weights (docs/intent_model.md)
  avp gen-intent-data SPLIT --episodes N --out FILE.npz   intent samples of one split (train|val|test|paper)
  avp train-trajectory [--scale full|dev|tiny] [--out DIR] [--workers W] [--threads T]
                                                   the learned trajectory predictor from scratch: data, training,
                                                   evaluation beside Bezier / constant velocity, weights
                                                   (docs/trajectory_model.md)
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


def cmd_experiment(args: argparse.Namespace) -> int:
    from avp_experiment.runner import run_command

    return run_command(args)


def cmd_launch(args: argparse.Namespace) -> int:
    from avp_bringup.graph import Graph, default_log_dir, ego_graph, fleet_graph, with_params, with_scene, with_sensing
    from avp_common.lifetime import hang_up_as_terminate

    log_dir = default_log_dir(args.log_dir)
    try:
        fleet = _fleet_methods(args)
        if fleet:  # a person at the wheel: real time, for the relays of the fleet too
            nodes = fleet_graph(fleet, scene=not args.no_scene, processes=args.processes,
                                sim_extra={"mode": "realtime"} if args.drivers else None)
        else:
            nodes = ego_graph(args.method, args.ego)
            if not args.no_scene:
                nodes = with_scene(nodes)
        if args.lot:
            from avp_world.lot import load_lot

            load_lot(args.lot)  # a bad lot: one line naming the file and the field, before any node starts
            nodes[0] = with_params(nodes[0], lot_file=str(Path(args.lot).resolve()))
        if args.drivers:
            if not 0 <= args.drivers <= 4:
                raise ValueError(f"--drivers: expected 0..4 driven cars, got {args.drivers}")
            nodes[0] = with_params(nodes[0], **{"drivers.count": args.drivers, "mode": "realtime"})
        nodes = with_sensing(nodes, args.sensing, args.detections)
    except ValueError as exc:
        print(f"[avp launch] {exc}", file=sys.stderr)
        return 2
    graph = Graph(nodes, log_dir, args.params)
    graph.start()
    where = f"namespaces /avp, /avp/ego0 .. /avp/ego{len(fleet) - 1}" if fleet else "namespace /avp"
    print(f"[avp] started {len(graph.procs)} nodes in {where}; logs in {log_dir}/")
    for name, p in graph.procs.items():
        print(f"[avp]   {name}: pid {p.pid}  log {log_dir / (name + '.log')}")
    print("[avp] Ctrl-C stops the graph")
    stop = {"flag": False}
    # SIGTERM and SIGHUP (its terminal closed) stop the graph as Ctrl-C does; SIGKILL cannot be caught, and the
    # nodes end then by themselves (avp_common.lifetime)
    hang_up_as_terminate(lambda *_: stop.update(flag=True))
    viewer = _foxglove(args, drive=args.drivers > 0, egos=len(fleet) or 1)  # (bridge, executor) or None
    if args.drivers:
        print(f"[avp] {args.drivers} driven car(s): `avp teleop --driver J` in another terminal, or Foxglove's Teleop "
              "panel on /avp/driver<J>/cmd_vel (--foxglove)")
    try:
        while not stop["flag"]:
            if viewer:
                viewer[1].spin_once(timeout_sec=0.5)
            else:
                time.sleep(0.5)
            dead = {n: rc for n, rc in graph.poll().items() if rc is not None}
            if dead and len(dead) == len(graph.procs):
                print(f"[avp] all nodes exited: {dead}")
                break
    except KeyboardInterrupt:
        pass
    finally:
        from avp_bringup.lifecycle import shutdown_lifecycle_nodes

        others = shutdown_lifecycle_nodes()  # planners swapped in by `avp swap-planner` (own processes)
        if viewer:
            viewer[0].close()
        graph.stop()
        print(f"[avp] graph stopped{'; shut down ' + ', '.join(others) if others else ''}")
    return 0


def _fleet_methods(args: argparse.Namespace) -> list[str]:
    """``--egos K [--methods M1,...]`` -> one method per ego ([] for the one-ego graph); ValueError naming the
    option for a bad value."""
    if args.egos == 1 and not args.methods:
        return []
    from avp_episode.fleet import parse_fleet

    if args.ego != "planner":
        raise ValueError("--egos/--methods and --ego scripted exclude each other")
    if args.methods and args.method:
        raise ValueError("--method and --methods exclude each other (--methods M1,M2,... names one per ego)")
    names = parse_fleet(args.methods or args.method or "bezier",
                        args.egos if not args.methods or args.egos > 1 else None, "--methods")
    return names if len(names) > 1 else []


def _foxglove(args: argparse.Namespace, drive: bool = False, egos: int = 1):
    """``--foxglove``: the Foxglove bridge node and an executor spinning it in this process, or None."""
    if not args.foxglove:
        return None
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from avp_viz import foxglove_cli

    if not rclpy.ok():
        rclpy.init()
    executor = SingleThreadedExecutor()
    bridge = foxglove_cli.start(args, drive, egos)
    executor.add_node(bridge)
    return bridge, executor


def cmd_swap_planner(args: argparse.Namespace) -> int:
    import rclpy

    from avp_bringup.lifecycle import LifecycleClient
    from avp_bringup.swap import SwapError, swap_planner

    rclpy.init()
    node = rclpy.create_node("avp_swap_planner")
    try:
        namespace = args.namespace
        if args.ego is not None:  # avp launch --egos K: ego i's pipeline is in /avp/ego<i>
            from avp_bringup.graph import ego_namespace

            namespace = ego_namespace(args.ego)
        report = swap_planner(LifecycleClient(node), namespace, profile=args.profile, node=args.node,
                              name=args.name, log_dir=Path(args.log_dir) if args.log_dir else None,
                              user_params=args.params, keep_old=args.keep_old, timeout=args.timeout)
    except SwapError as exc:
        print(f"[avp swap-planner] {exc}", file=sys.stderr)
        return 2
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    started = f" (pid {report.pid}, log {report.log}, observation {report.observation})" if report.pid else ""
    print(f"[avp swap-planner] active planner: {report.new}{started}; deactivated {report.deactivated or 'none'}"
          f" ({report.gap_s * 1000:.0f} ms without a planner); shut down {report.shut_down or 'none'}")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    import subprocess

    from avp_bringup.graph import avp_root

    script = avp_root() / "bench" / f"bench_{args.which}.py"
    if not script.is_file():
        print(f"[avp bench] no benchmark script {script}", file=sys.stderr)
        return 2
    return subprocess.call([sys.executable, str(script), *args.rest])


def cmd_params(args: argparse.Namespace) -> int:
    from avp_common.params import markdown_table
    from avp_perception.params import BELIEF_PARAMS, PREDICTION_PARAMS
    from avp_planner.examples.minimal_planner import MINIMAL_PARAMS
    from avp_planner.params import PLANNER_PARAMS
    from avp_planner.reservation_node import RESERVATION_PARAMS
    from avp_planner.scripted_driver_node import DRIVER_PARAMS
    from avp_planner.v2v_node import V2V_PARAMS
    from avp_sim.params import SIM_PARAMS
    from avp_tracking.params import TRACKER_NODE_PARAMS
    from avp_viz.scene_node import SCENE_PARAMS

    tables = {"avp_sim": SIM_PARAMS, "avp_tracker": TRACKER_NODE_PARAMS, "avp_belief": BELIEF_PARAMS,
              "avp_prediction": PREDICTION_PARAMS,
              "avp_planner": PLANNER_PARAMS, "scripted_driver": DRIVER_PARAMS, "minimal_planner": MINIMAL_PARAMS,
              "avp_scene": SCENE_PARAMS, "avp_reservation": RESERVATION_PARAMS,
              "avp_v2v": V2V_PARAMS}
    for name, specs in tables.items():
        if args.node and args.node != name:
            continue
        print(f"### {name}\n\n{markdown_table(specs)}\n")
    return 0


def cmd_train_intent(args: argparse.Namespace) -> int:
    from avp_training.run import cmd_train_intent as run

    return run(args)


def cmd_gen_intent_data(args: argparse.Namespace) -> int:
    from avp_training.run import cmd_gen_intent_data as run

    return run(args)


def cmd_train_trajectory(args: argparse.Namespace) -> int:
    from avp_trajectory_training.run import cmd_train_trajectory as run

    return run(args)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return _in_domain(args)


def build_parser() -> argparse.ArgumentParser:
    """The ``avp`` argument parser: one sub-command per tool (see the module docstring)."""
    from avp_bag import cli as bag_cli
    from avp_bringup import demo, why
    from avp_bringup.compose import add_processes_argument
    from avp_bringup.graph import add_sensing_arguments
    from avp_common.version import __version__
    from avp_teleop import teleop
    from avp_viz import foxglove_cli

    parser = argparse.ArgumentParser(prog="avp", description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    parser.add_argument("--version", action="version", version=f"avp {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("launch", help="start the node graph")
    p.add_argument("--params", help="extra ROS 2 parameter file applied after the defaults")
    p.add_argument("--log-dir")
    p.add_argument("--ego", choices=("planner", "scripted"), default="planner", help="the ego's node")
    p.add_argument("--method", help="a Table I method profile (bezier, constant_velocity, hybrid_astar, learned, "
                   "implicit, nawaz or a profile file): the same 4 nodes with the profile's parameters")
    p.add_argument("--lot", help="lot map YAML to simulate and plan on (default: the bundled paper lot)")
    p.add_argument("--egos", type=int, default=1, help="automated cars, 1-8: one pipeline each in /avp/ego<i> "
                   "(docs/world.md, 'Several egos')")
    p.add_argument("--methods", help="one method per ego, comma-separated (e.g. bezier,blind); sets --egos")
    p.add_argument("--drivers", type=int, default=0, help="cars a person drives (avp teleop, Foxglove's Teleop panel) "
                   "on /avp/driver<j>/cmd_vel; the simulator then runs in real time (docs/teleop.md)")
    p.add_argument("--no-scene", action="store_true", help="leave out the scene node (/tf, /tf_static, viz/scene)")
    add_sensing_arguments(p)
    add_processes_argument(p)
    foxglove_cli.add_arguments(p)
    p.set_defaults(func=cmd_launch)
    p = sub.add_parser("demo", help="run one seeded episode through the live graph")
    demo.add_arguments(p)
    p.set_defaults(func=demo.run)
    p = sub.add_parser("teleop", help="drive a driven car of the running graph from the keyboard (docs/teleop.md)")
    teleop.add_arguments(p)
    p.set_defaults(func=teleop.run)
    bag_cli.add_commands(sub)
    why.add_command(sub)
    _add_live_commands(sub)
    _add_offline_commands(sub)
    return parser


def _add_live_commands(sub) -> None:
    """swap-planner: a tool for a running graph."""
    p = sub.add_parser("swap-planner", help="replace the running planner while the simulator keeps stepping")
    p.add_argument("profile", nargs="?", help="planner profile: a name of avp_planner/config/profiles/ or a "
                   "parameter YAML; starts a new planner process with it")
    p.add_argument("--node", help="bring up this running lifecycle node instead (e.g. /avp/my_planner)")
    p.add_argument("--name", help="node name of the new planner (default avp_planner_<profile>)")
    p.add_argument("--params", help="extra parameter file for the new planner (as given to avp launch)")
    p.add_argument("--log-dir", help="where the new planner's log goes (default out/logs/swap-<time>/)")
    p.add_argument("--namespace", default="/avp")
    p.add_argument("--ego", type=int, choices=range(8), metavar="I",
                   help="swap ego I's planner in a graph of several egos (namespace /avp/ego<I>); the others drive on")
    p.add_argument("--keep-old", action="store_true", help="leave the old planner inactive instead of shutting "
                   "it down")
    p.add_argument("--timeout", type=float, default=30.0, help="per lifecycle call / start-up [s]")
    p.set_defaults(func=cmd_swap_planner)


def _add_offline_commands(sub) -> None:
    """experiment, bench, params and the training commands."""
    p = sub.add_parser("experiment", help="the Table I runner (episodes x methods x modes, resumable)")
    from avp_experiment.runner import add_arguments

    add_arguments(p)
    p.set_defaults(func=cmd_experiment)
    p = sub.add_parser("bench", help="run a benchmark script of bench/")
    p.add_argument("which", choices=("sensing", "planner", "perception", "soak", "live_latency", "learned",
                                     "closed_loop"))
    p.add_argument("rest", nargs=argparse.REMAINDER)
    p.set_defaults(func=cmd_bench)
    p = sub.add_parser("params", help="print parameter tables")
    p.add_argument("node", nargs="?")
    p.set_defaults(func=cmd_params)
    from avp_training.run import add_gen_arguments, add_intent_arguments

    p = sub.add_parser("train-intent", help="train the intent CNN from scratch (docs/intent_model.md)")
    add_intent_arguments(p)
    p.set_defaults(func=cmd_train_intent)
    p = sub.add_parser("gen-intent-data", help="generate intent-model samples of one split")
    add_gen_arguments(p)
    p.set_defaults(func=cmd_gen_intent_data)
    from avp_trajectory_training.run import add_arguments as add_trajectory_arguments

    p = sub.add_parser("train-trajectory", help="train the learned trajectory predictor (docs/trajectory_model.md)")
    add_trajectory_arguments(p)
    p.set_defaults(func=cmd_train_trajectory)


def _in_domain(args: argparse.Namespace) -> int:
    """Run the command in its DDS domain (avp_bringup.domain): a new graph claims a free ROS_DOMAIN_ID unless the
    environment sets one; a tool for a running graph joins the one running graph's domain."""
    from avp_bringup import domain

    starts_graph = args.command in ("launch", "demo") or (args.command == "experiment"
                                                          and getattr(args, "transport", "") == "ros")
    try:
        if starts_graph:
            d, claimed = domain.claim_domain()
            if claimed:
                print(f"[avp] ROS_DOMAIN_ID={d} (a domain of this graph's own; set ROS_DOMAIN_ID to choose one)",
                      flush=True)
        elif args.command in ("swap-planner", "record", "replay", "teleop"):
            domain.join_running_domain()
    except (RuntimeError, ValueError) as exc:
        print(f"[avp {args.command}] {exc}", file=sys.stderr)
        return 2
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())

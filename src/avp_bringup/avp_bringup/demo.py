"""``avp demo``: one seeded episode through the live graph over DDS, recorded to a bag (docs/experiment.md, "The
demo"). Writes metrics.json (with the closed-loop step time), episode.png and episode.gif from the bag.

Lock-step by default (the wall-clock caps lifted, so the episode is the same whatever the machine's load);
``--realtime`` steps the simulator at 1/dt wall rate.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from avp_bringup.compose import add_processes_argument
from avp_bringup.graph import EGO_NODES, add_sensing_arguments, avp_root
from avp_viz import foxglove_cli


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seed", type=int, default=1, help="scenario seed (1: a car in view early; parks at ~17 s)")
    p.add_argument("--non-reactive", action="store_true")
    p.add_argument("--ego", choices=("planner", "scripted"), default="planner", help="the ego's node")
    p.add_argument("--method", default=None, help="a Table I method profile (bezier, constant_velocity, "
                   "hybrid_astar, implicit, nawaz or a profile file) [default: bezier; ignored with --ego scripted]")
    p.add_argument("--realtime", action="store_true", help="the simulator steps at 1/dt wall rate (mode: realtime) "
                   "instead of lock-step; the closed-loop step time then decides whether commands come in time")
    p.add_argument("--egos", type=int, default=1, help="automated cars, 1-8, each a pipeline of --method in "
                   "/avp/ego<i> (docs/world.md, 'Several egos'); the GIF shows all of them from ego 0's view")
    p.add_argument("--drive", action="store_true", help="a car you drive in the same lot (real time): `avp teleop` in "
                   "another terminal, or Foxglove's Teleop panel with --foxglove (docs/teleop.md)")
    p.add_argument("--no-gif", action="store_true", help="do not write episode.gif")
    p.add_argument("--t-final", type=float, default=None)
    p.add_argument("--out", default=str(avp_root() / "out" / "demo"))
    p.add_argument("--params")
    p.add_argument("--scenario", choices=("paper", "busy"), default=None,
                   help="scenario family (the simulator's scenario.family): paper (§VI-A, default) or busy (20+ "
                   "parking and exiting cars, 10+ pedestrians; docs/world.md)")
    p.add_argument("--lot", help="lot map YAML to simulate and plan on (default: the bundled paper lot; the scenario "
                   "comes from its scenario: block or its geometry)")
    p.add_argument("--timeout", type=float, default=600.0, help="wall-clock limit [s]")
    p.add_argument("--bag", help="where to record the demo's bag (default bags/demo_seed<N>_<time>)")
    foxglove_cli.add_arguments(p)
    add_sensing_arguments(p)
    p.add_argument("--no-scene", action="store_true",
                   help="leave out the scene node: the bag then has no /tf, /tf_static, viz/scene for viewers")
    add_processes_argument(p)


def run(args: argparse.Namespace) -> int:
    """One seeded episode through the live graph; exit code 0 when it ran to its end."""
    import rclpy

    from avp_bag.recorder import BagRecorder
    from avp_bag.writer import BagWriteError

    try:
        nodes = _demo_nodes(args)
    except ValueError as exc:
        print(f"[avp demo] {exc}", file=sys.stderr)
        return 2
    from avp_world.lot import load_bundled_lot, load_lot

    try:
        lot = load_lot(args.lot) if args.lot else load_bundled_lot()
    except ValueError as exc:  # LotMapError: one line naming the file and the field
        print(f"[avp demo] {exc}", file=sys.stderr)
        return 2
    bag = Path(args.bag) if args.bag else avp_root() / "bags" / f"demo_seed{args.seed}_{time.strftime('%Y%m%d-%H%M%S')}"
    bag.parent.mkdir(parents=True, exist_ok=True)
    rclpy.init()
    try:
        from avp_bag.recorder import fleet_topics

        topics = fleet_topics(args.egos)
        if getattr(args, "drive", False):  # what the person sent
            topics["/avp/driver0/cmd_vel"] = ("geometry_msgs/msg/Twist", False)
            topics["/avp/driver0/episode_status"] = ("avp_msgs/msg/EpisodeStatus", True)
        recorder = BagRecorder(bag, topics, warn_unmatched_after=LATE_MATCH_WAIT)  # its warning ends the wait
    except BagWriteError as exc:
        print(f"[avp demo] {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    from avp_common.lifetime import interrupt_on_terminate

    interrupt_on_terminate()  # SIGTERM, SIGHUP: the graph stopped and the bag closed, as after Ctrl-C
    try:
        rc, result = _run_episode(args, nodes, recorder, lot)
    except KeyboardInterrupt:
        print(f"[avp demo] stopped before the episode's end; the bag so far: {bag}", file=sys.stderr)
        return 130
    if rc:
        return rc
    if recorder.error:
        print(f"[avp demo] the episode ran to its end but {recorder.error}", file=sys.stderr)
    _report(args, bag, *result)
    return 0


def _mode(args: argparse.Namespace) -> str:
    return "realtime" if args.realtime or getattr(args, "drive", False) else "lockstep"


def _ego_node(nodes) -> str:
    """The name of the graph's ego node (the planner or the scripted driver; the scene node, a viewer, comes
    after it in the graph)."""
    egos = {spec.name for spec in EGO_NODES.values()}
    return next((n.name for n in reversed(nodes) if n.name in egos), nodes[-1].name)


def _method(args: argparse.Namespace) -> str:
    return args.method or "scripted"


def _demo_nodes(args: argparse.Namespace) -> list:
    """The graph of ``--method`` (bezier by default) with the simulator set up for one episode started by
    ``reset_episode`` (ValueError on conflicting options)."""
    from avp_bringup.graph import ego_graph, fleet_graph, with_params, with_scene, with_sensing

    if args.ego == "planner" and not args.method:
        args.method = "bezier"  # the paper's method
    if getattr(args, "drive", False):
        args.realtime = True  # lock-step never waits for a person
    if not 1 <= args.egos <= 8:
        raise ValueError(f"--egos: expected 1..8 automated cars, got {args.egos}")
    if args.egos > 1:
        if args.ego != "planner":
            raise ValueError("--egos and --ego scripted exclude each other")
        # the mode reaches the V2V node (and a reservation book) too: in real time they never wait for a decision
        nodes = fleet_graph([args.method] * args.egos, deterministic=not args.realtime, sim_extra={"mode": _mode(args)},
                            scene=not getattr(args, "no_scene", False), processes=getattr(args, "processes", "ego"))
    else:
        # lock-step: the wall-clock caps lifted, so the episode is the same whatever the machine's load
        nodes = ego_graph(args.method, args.ego, deterministic=not args.realtime)
        if not getattr(args, "no_scene", False):
            nodes = with_scene(nodes)
    sim = nodes[0]
    # the episode is started with reset_episode once the whole graph is up and discovered both ways (a volatile
    # reader that matches after step 0 was sent never gets it: lock-step would re-send after lockstep_timeout, real
    # time would run without the pipeline); in lock-step step 0 also waits for the graph's observation subscribers
    # plus our monitor and recorder
    # + our recorder, and our monitor (one ego: it reads /avp/observation)
    plus = 2 if args.egos == 1 else 1
    extra = {"seed": args.seed, "reactive": not args.non_reactive, "mode": _mode(args), "autostart": False,
             "min_subscribers": sim.extra_params.get("min_subscribers", 1) + plus, "min_debug_subscribers": 2}
    if args.t_final is not None:
        extra["t_final"] = args.t_final
    if args.lot:
        extra["lot_file"] = str(Path(args.lot).resolve())
    if args.scenario:
        extra["scenario.family"] = args.scenario
    if getattr(args, "drive", False):  # a person drives car 0 (docs/teleop.md), through the gate after the ego
        extra.update({"drivers.count": 1, "drivers.enter_at": 3.0})
    nodes[0] = with_params(sim, **extra)
    return with_sensing(nodes, getattr(args, "sensing", "exact"), getattr(args, "detections", None))


#: the recorder's topics the episode cannot be read back without (avp_bag.episode.read_episode): the demo starts the
#: episode only once the recorder's readers have matched their writers
RECORDED_FIRST = ("/clock", "/avp/lot_map", "/avp/debug/ground_truth", "/avp/episode_status")
#: seconds the recorder's other readers get to match the writers the graph shows, once the graph is up
LATE_MATCH_WAIT = 10.0


def _check_bag(recorder, monitor) -> None:
    """One warning when the bag holds fewer ground-truth messages than the episode had steps (one per step, step 0
    included): what the recorder missed is named rather than found by the first reader of the bag."""
    steps = int(monitor.status.metrics.steps) + 1
    n = recorder.counts.get("/avp/debug/ground_truth", 0)
    if n < steps and not recorder.error:
        print(f"[avp demo] warning: the bag holds {n} of the episode's {steps} ground-truth messages (recorded: "
              f"{dict(sorted(recorder.counts.items()))})", file=sys.stderr, flush=True)


def _scenes_behind(recorder, monitor) -> bool:
    """One ego with a scene node (its scenes are being recorded): fewer scenes in the bag than the episode's steps."""
    n = recorder.counts.get("/avp/viz/scene", 0)
    return 0 < n < int(monitor.status.metrics.steps)


def _run_episode(args: argparse.Namespace, nodes: list, recorder, lot) -> tuple[int, tuple]:
    """Start the graph, run the episode to its end while the monitor and the recorder listen, write
    metrics.json and episode.png; returns (exit code, (metrics, latency, wall seconds))."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from avp_bringup.graph import Graph
    from avp_common.node_main import freeze_start_up_heap
    from avp_episode.metrics import lot_record
    from avp_monitor.monitor import EpisodeMonitor
    from avp_msgs.srv import ResetEpisode

    out = Path(args.out)
    log_dir = out / "logs"
    monitor = EpisodeMonitor(egos=args.egos)
    executor = SingleThreadedExecutor()
    executor.add_node(monitor)
    executor.add_node(recorder)
    bridge = foxglove_cli.start(args, getattr(args, "drive", False), args.egos)  # --foxglove: live (and Teleop)
    if bridge is not None:
        executor.add_node(bridge)
    graph = Graph(nodes, log_dir, args.params)
    t0 = time.monotonic()
    graph.start()
    egos = f"{args.egos} egos of " if args.egos > 1 else ""
    print(f"[avp demo] {egos}method {_method(args)}, seed {args.seed} ({'non-' if args.non_reactive else ''}"
          f"reactive), {_mode(args)}, through the live graph over DDS ({', '.join(n.key for n in nodes)}); node logs "
          f"in {log_dir}/")
    if getattr(args, "drive", False):
        print("[avp demo] drive car 0: `avp teleop` in another terminal (arrows/wasd, space stops), or Foxglove's "
              "Teleop panel on /avp/driver0/cmd_vel (--foxglove); it enters through the gate 3 s in", flush=True)
    try:
        n_subs = nodes[0].extra_params["min_subscribers"]
        freeze_start_up_heap()  # the monitor and recorder read each step on time (avp_common.node_main)
        _start_episode(monitor, recorder, executor, graph, ResetEpisode, args, n_subs, log_dir)
        while not monitor.finished:
            executor.spin_once(timeout_sec=0.2)
            dead = {n: rc for n, rc in graph.poll().items() if rc is not None}
            if dead:
                print(f"[avp demo] node(s) exited early: {dead}; see {log_dir}/", file=sys.stderr)
                return 1, ()
            if time.monotonic() - t0 > args.timeout:
                print(f"[avp demo] no episode end after {args.timeout} s wall time", file=sys.stderr)
                return 1, ()
        wall = time.monotonic() - t0
        t_end = time.monotonic()
        # drain: the last step's messages to the monitor and the bag, at least 1 s, and until the bag holds the scene
        # of every step (the scene node draws step k once the planner's decision k is in: on a loaded machine that can
        # come more than a second after the episode's end), 15 s at most
        while time.monotonic() - t_end < 1.0 or (_scenes_behind(recorder, monitor) and time.monotonic() - t_end < 15.0):
            executor.spin_once(timeout_sec=0.05)
        latency = monitor.latency_dict(_mode(args))
        extra = {"wall_time_s": round(wall, 2), "method": _method(args), "lot": lot_record(lot),
                 "ego_node": _ego_node(nodes), "closed_loop_step_time": latency}
        if args.egos > 1:
            extra["egos"] = monitor.ego_states()
        metrics = monitor.write(lot, out, extra)
        _check_bag(recorder, monitor)
    except RuntimeError as exc:
        print(f"[avp demo] {exc}", file=sys.stderr)
        return 1, ()
    finally:
        graph.stop()
        recorder.close()
        if bridge is not None:
            bridge.close()
            bridge.destroy_node()
        monitor.destroy_node()
        recorder.destroy_node()
        rclpy.try_shutdown()
    return 0, (metrics, latency, wall)


def _report(args: argparse.Namespace, bag: Path, metrics: dict, latency: dict, wall: float) -> None:
    """Print where everything went and write the GIF from the bag."""
    out = Path(args.out)
    print(f"[avp demo] bag: {bag}\n[avp demo]   replay it: avp replay {bag}   metrics from it: avp metrics {bag}")
    print(f"[avp demo] {metrics['state']} after {metrics['sim_time']:.1f} s sim time ({wall:.1f} s wall); "
          f"wrote {out / 'metrics.json'} and {out / 'episode.png'}")
    for i, e in enumerate(metrics.get("egos", [])):
        print(f"[avp demo]   ego {i}: {e['state']}" + (f", parked in spot {e['parked_spot_id']} after "
                                                         f"{e['parking_time']:.1f} s" if e["success"] else ""))
    print(f"[avp demo] {latency_line(latency)}")
    if not args.no_gif:
        from avp_viz.episode_video import episode_gif

        gif = out / "episode.gif"
        info = episode_gif(bag, gif, title=f"{_method(args)} seed {args.seed}", egos=args.egos)
        print(f"[avp demo] wrote {gif} ({info['frames']} frames, every {info['stride']}. step, "
              f"{info['bytes'] / 1e6:.1f} MB) from the bag's topics")


def latency_line(lat: dict) -> str:
    """One line on the closed-loop step time of the monitor's latency dict."""
    if not lat.get("steps"):
        return "closed-loop step time: no step answered"
    late = f", {lat['late_steps']} step(s) answered too late (ego held still)" if "late_steps" in lat else ""
    return (f"closed-loop step time (observation k sent -> command k received, {lat['sim_mode']}, {lat['steps']} "
            f"steps): median {lat['median_ms']:.1f} ms, p95 {lat['p95_ms']:.1f} ms, max {lat['max_ms']:.1f} ms "
            f"(target p95 <= 100 ms){late}")


def _start_episode(monitor, recorder, executor, graph, srv_type, args, n_obs_subs: int, log_dir: Path,
                   timeout: float = 60.0) -> None:
    """Wait until every node is up (observation subscribers, the ego's cmd publisher, the reset service), the
    monitor's own readers and the recorder's readers of the episode (:data:`RECORDED_FIRST`) have matched their
    writers, and a second for discovery to settle, then start the episode with reset_episode (RuntimeError when
    that fails). The recorder's other readers get up to :data:`LATE_MATCH_WAIT` s more; one that still has not
    matched a writer the graph shows (a foreign publisher of incompatible QoS, say) is named in the recorder's warning
    (:attr:`avp_bag.recorder.BagRecorder.warn_unmatched_after`, set to the same time)."""
    from avp_common.services import call_once

    client = monitor.create_client(srv_type, "reset_episode")
    prefixes = [f"/avp/ego{i}" for i in range(args.egos)] if args.egos > 1 else ["/avp"]
    t0 = time.monotonic()
    while not (client.service_is_ready() and monitor.inputs_matched() and not recorder.unmatched(RECORDED_FIRST)
               and all(monitor.count_subscribers(f"{p}/observation") >= n_obs_subs
                       and monitor.count_publishers(f"{p}/cmd") >= 1 for p in prefixes)):
        executor.spin_once(timeout_sec=0.1)
        dead = {n: rc for n, rc in graph.poll().items() if rc is not None}
        if dead or time.monotonic() - t0 > timeout:
            late = recorder.unmatched(RECORDED_FIRST)
            raise RuntimeError(f"graph not up ({dead or f'after {timeout} s'}"
                               f"{f'; the recorder matched no writer of {late}' if late else ''}); see {log_dir}/")
    t1 = time.monotonic()
    # matching completes both ways; the latched lot map reaches every node; the recorder's other readers match
    while time.monotonic() - t1 < 1.0 or (recorder.unmatched() and time.monotonic() - t1 < LATE_MATCH_WAIT):
        executor.spin_once(timeout_sec=0.05)
    seed, reactive = int(args.seed), not args.non_reactive
    try:  # sent once (a second reset would restart the running episode); its status also shows it happened
        res = call_once(client, srv_type.Request(seed=seed, reactive=reactive),
                        lambda s: executor.spin_once(timeout_sec=s),
                        lambda: monitor.status is not None and (monitor.status.seed, monitor.status.reactive)
                        == (seed, reactive), timeout=30.0)
    except TimeoutError as exc:
        raise RuntimeError(f"reset_episode failed: {exc}") from None
    if res is not None and not res.success:
        raise RuntimeError(f"reset_episode failed: {res.message}")

"""The ``avp`` sub-commands of bags: record, replay, merge-bag, metrics (the ``avp`` command of avp_bringup adds them;
rosbag2 stands apart from the launcher, as here)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


def cmd_merge_bag(args: argparse.Namespace) -> int:
    from avp_bag.merge import merge_bag

    try:
        n = merge_bag(args.bag, args.out)
    except (ValueError, OSError) as exc:  # a damaged or foreign bag, an existing OUT: one line naming the file
        print(f"[avp merge-bag] {exc}", file=sys.stderr)
        return 2
    print(f"[avp merge-bag] {n} messages of {args.bag} -> {args.out}")
    return 0


def cmd_record(args: argparse.Namespace) -> int:
    import rclpy

    from avp_bag.recorder import GRAPH_TOPICS, OPTIONAL_TOPICS, BagRecorder

    known = {**GRAPH_TOPICS, **OPTIONAL_TOPICS}
    topics = GRAPH_TOPICS
    if args.topics:
        unknown = [t for t in args.topics if t not in known]
        if unknown:
            print(f"[avp record] unknown topic(s) {unknown}; known: {sorted(known)}", file=sys.stderr)
            return 2
        topics = {t: known[t] for t in args.topics}
    rclpy.init()
    from avp_bag.writer import BagWriteError

    try:
        rec = BagRecorder(Path(args.out), topics, storage=args.storage, split_period=args.split_period,
                          foreign=args.foreign)
    except BagWriteError as exc:
        print(f"[avp record] {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    print(f"[avp record] recording {len(topics)} topics to {args.out} ({args.storage}); Ctrl-C stops")
    stop = {"flag": False}
    from avp_common.lifetime import hang_up_as_terminate

    hang_up_as_terminate(lambda *_: stop.update(flag=True))  # SIGTERM, SIGHUP: the bag closed cleanly
    t0 = time.monotonic()
    try:
        while not stop["flag"] and (args.duration is None or time.monotonic() - t0 < args.duration):
            rclpy.spin_once(rec, timeout_sec=0.1)
            if rec.error:
                break
    except KeyboardInterrupt:
        pass
    finally:
        rec.close()
        if rec.error:
            print(f"[avp record] {rec.error}", file=sys.stderr)
        else:
            print(f"[avp record] closed {args.out}: {rec.counts}")
        rec.destroy_node()
        rclpy.try_shutdown()
    return 1 if rec.error else 0


def cmd_replay(args: argparse.Namespace) -> int:
    import rclpy

    from avp_bag.replay import BagReplayer

    rclpy.init()
    try:
        rep = BagReplayer(Path(args.bag), args.topics)
    except (ValueError, OSError) as exc:
        print(f"[avp replay] {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    print(f"[avp replay] {args.bag}: {len(rep.connections)} topics at rate {args.rate}, from +{args.start} s")
    try:
        # --wait-subscribers: first until our writers have matched a reader on every topic, then --delay, in which
        # the readers' side of the match completes (a volatile message written before it is lost to that reader)
        if args.wait_subscribers and not rep.wait_for_subscribers(list(rep.pubs), timeout=30.0):
            print("[avp replay] --wait-subscribers: no subscriber matched every topic within 30 s; playing anyway",
                  file=sys.stderr)
        time.sleep(args.delay)  # let subscribers discover the publishers (and, after a match, finish matching)
        n = rep.play(rate=args.rate, start_offset=args.start)
        print(f"[avp replay] published {n} messages")
    except KeyboardInterrupt:
        pass
    except ValueError as exc:  # a corrupt split (bagread.BagReadError): what preceded it was published
        print(f"[avp replay] {exc}; published {rep.published} messages before it", file=sys.stderr)
        return 2
    finally:
        rep.close()
        rep.destroy_node()
        rclpy.try_shutdown()
    return 0


def cmd_metrics(args: argparse.Namespace) -> int:
    import json

    from avp_bag.episode import metrics_from_bag

    if args.ego is not None or args.driver is not None:
        from avp_bag.episode import ego_metrics_from_bag

        try:
            who = args.driver if args.driver is not None else args.ego
            print(json.dumps(ego_metrics_from_bag(Path(args.bag), who, driver=args.driver is not None), indent=2))
        except (ValueError, OSError) as exc:
            print(f"[avp metrics] {exc}", file=sys.stderr)
            return 2
        return 0
    try:
        recomputed, live = metrics_from_bag(Path(args.bag))
    except (ValueError, OSError) as exc:
        print(f"[avp metrics] {exc}", file=sys.stderr)
        return 2
    print(json.dumps({"recomputed_from_ground_truth": recomputed, "live_episode_status": live}, indent=2))
    same = recomputed == live
    print(f"[avp metrics] recomputed metrics {'equal' if same else 'DIFFER FROM'} the live ones")
    return 0 if same else 1


def add_commands(sub) -> None:
    """record, replay, merge-bag, metrics: the sub-commands of bags."""
    p = sub.add_parser("record", help="record the graph to a rosbag2")
    p.add_argument("out")
    p.add_argument("--topics", nargs="+")
    p.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    p.add_argument("--duration", type=float, default=None, help="stop after this many wall seconds")
    p.add_argument("--split-period", type=float, default=1.0,
                   help="finish a storage file every this many wall seconds (a crash loses at most the open one)")
    p.add_argument("--foreign", action="store_true",
                   help="also record messages without the graph's tag on the tagged topics (another publisher's)")
    p.set_defaults(func=cmd_record)
    p = sub.add_parser("replay", help="republish a bag with its sim clock")
    p.add_argument("bag")
    p.add_argument("--rate", type=float, default=1.0, help="1 = as recorded, 0 = as fast as possible")
    p.add_argument("--start", type=float, default=0.0, help="start offset into the bag [s]")
    p.add_argument("--topics", nargs="+")
    p.add_argument("--delay", type=float, default=1.0, help="wall seconds to wait for subscribers first")
    p.add_argument("--wait-subscribers", action="store_true",
                   help="before --delay, wait (up to 30 s) until every replayed topic has a subscriber")
    p.set_defaults(func=cmd_replay)
    p = sub.add_parser("merge-bag", help="one MCAP file of a (split) bag, for viewers that open one file")
    p.add_argument("bag")
    p.add_argument("out", help="the new .mcap file (never overwritten)")
    p.set_defaults(func=cmd_merge_bag)
    p = sub.add_parser("metrics", help="recompute an episode's metrics from a bag")
    p.add_argument("bag")
    p.add_argument("--ego", type=int, default=None, metavar="I",
                   help="ego I of a bag of several egos: its own episode status (the recomputation covers one ego)")
    p.add_argument("--driver", type=int, default=None, metavar="J",
                   help="driven car J of a bag of avp demo --drive: the agents it made brake, its collisions")
    p.set_defaults(func=cmd_metrics)

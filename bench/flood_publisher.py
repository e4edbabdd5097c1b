#!/usr/bin/env python3
"""A foreign publisher gone wild: floods `cmd`, `observation` and `beliefs` of a running graph.

On each topic it publishes ``--rate`` messages a second, cycling through four kinds a real fault or attacker
would send:

* ``untagged``: a well-formed message of its own (a 3 m/s command, an empty observation, beliefs of 0.5) with
  the stamp of the graph's latest step, but without the user's HMAC tag;
* ``forged``: the same with a tag of the right form that does not verify (``frame#<64 hex digits>``);
* ``garbage``: NaN/inf content under a forged tag;
* ``replay``: the graph's own latest message on that topic, tagged and byte for byte (a copy: it verifies).

With ``--episode-replays`` (docs/bad_input.md row 51) two more kinds, as a replayed recording would send:

* ``replay_first``: the first message it saw on that topic (the running episode's step 0, say), byte for byte;
* ``earlier_episode``: the latest message re-tagged as one of the episode before (its episode id - 1) — what a
  bag of an earlier episode holds; this needs the user's key (``$AVP_CMD_KEY_FILE``), as a replay of the user's
  own recording has.

It joins the graph's ROS_DOMAIN_ID (from the environment). Once its publishers exist it prints the line
``flooding``, so a caller can start the graph only when the flood is on (a loaded machine takes seconds to import
rclpy). When it stops (``--duration`` or SIGTERM/SIGINT, also one that comes during its start-up) it prints one JSON
line: messages sent per topic and kind, and the achieved rate.

With ``--bad-resets HZ`` it also calls the simulator's ``reset_episode`` HZ times a second with the hostile
requests of bench/hostile_requests.py (10 000 vehicles, 1 MB of YAML, deep nesting, paths outside the served
directories, ...), without waiting for the answers; each must be refused and change nothing.

Usage: python bench/flood_publisher.py [--rate 1000] [--duration 30] [--topics /avp/cmd,/avp/observation,...]
       [--episode-replays] [--bad-resets 2]
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import time
from pathlib import Path

KINDS = ("untagged", "forged", "garbage", "replay")
EPISODE_KINDS = ("replay_first", "earlier_episode")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rate", type=float, default=1000.0, help="messages per second on each topic")
    ap.add_argument("--duration", type=float, default=30.0, help="seconds to flood")
    ap.add_argument("--topics", default="/avp/cmd,/avp/observation,/avp/beliefs")
    ap.add_argument("--episode-replays", action="store_true",
                    help="also replay the first message seen and re-tag the latest as of the episode before")
    ap.add_argument("--bad-resets", type=float, default=0.0, help="hostile reset_episode requests a second")
    args = ap.parse_args()
    stop = {"flag": False}
    signal.signal(signal.SIGTERM, lambda *_: stop.update(flag=True))  # first: a SIGTERM during start-up still reports
    kinds = KINDS + (EPISODE_KINDS if args.episode_replays else ())

    import rclpy
    from geometry_msgs.msg import TwistStamped
    from rclpy.serialization import deserialize_message, serialize_message

    from avp_common.qos import STEP
    from avp_msgs.msg import Observation, SpotBeliefs

    types = {"/avp/cmd": TwistStamped, "/avp/observation": Observation, "/avp/beliefs": SpotBeliefs}
    topics = [t for t in args.topics.split(",") if t]
    unknown = [t for t in topics if t not in types]
    if unknown:
        print(f"flood_publisher: --topics {unknown}: one of {sorted(types)}", file=sys.stderr)
        return 2
    from rclpy.signals import SignalHandlerOptions

    # rclpy's own handlers would shut the context down on SIGTERM, and a publish in the loop below would then raise
    # before the report is printed: ours (set above) only ends the loop
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("avp_flooder")
    from avp_common.msg_auth import load_key, verify

    try:  # with the user's key (as a replay of the user's own bag has it) the graph's messages are told apart
        own: bytes | None = load_key()
    except OSError:
        own = None
    latest: dict[str, bytes] = {}
    newest: dict[str, int] = {}  # the newest episode seen per topic
    first: dict[str, bytes] = {}
    stamp = {"sec": 0, "nanosec": 0, "step": 0}

    def keep(topic: str):
        def cb(raw: bytes) -> None:
            if own is not None and not verify(own, raw):
                return  # our own flood (it is on the same topic): only the graph's messages are replayed
            from avp_common.msg_auth import episode_of

            ep = episode_of(deserialize_message(raw, types.get(topic, Observation)).header.frame_id)
            if ep < newest.get(topic, 0):
                return  # our own re-tagged copies of the episode before
            newest[topic] = ep
            latest[topic] = bytes(raw)
            first.setdefault(topic, bytes(raw))
            if topic == "/avp/observation":
                m = deserialize_message(raw, Observation)
                stamp.update(sec=m.header.stamp.sec, nanosec=m.header.stamp.nanosec, step=m.step)
        return cb

    pubs = {t: node.create_publisher(types[t], t, STEP) for t in topics}
    subs = [node.create_subscription(types[t], t, keep(t), STEP, raw=True) for t in set(topics) | {"/avp/observation"}]

    def forge(msg, bad: bool):
        msg.header.stamp.sec, msg.header.stamp.nanosec = stamp["sec"], stamp["nanosec"]
        msg.header.frame_id = ("map" if not isinstance(msg, TwistStamped) else "ego") + "#" + "ab" * 32
        if isinstance(msg, TwistStamped):
            msg.twist.linear.x = math.nan if bad else 3.0
            msg.twist.angular.z = math.inf if bad else 0.0
        elif isinstance(msg, SpotBeliefs):
            msg.spot_ids = [0, 1, 2]
            msg.beliefs = [math.nan, -1.0, 7.0] if bad else [0.5, 0.5, 0.5]
        else:
            msg.step = stamp["step"]
            msg.ego_pose.x = math.nan if bad else 0.0
        return msg

    def make(topic: str, kind: str):
        if kind == "replay":
            return latest.get(topic)
        if kind == "replay_first":
            return first.get(topic)
        if kind == "earlier_episode":
            if topic not in latest:
                return None
            from avp_common.msg_auth import episode_of, sign

            msg = deserialize_message(latest[topic], types[topic])
            return sign(own, msg, max(episode_of(msg.header.frame_id) - 1, 0)) if own is not None else None
        msg = forge(types[topic](), kind == "garbage")
        if kind == "untagged":
            msg.header.frame_id = msg.header.frame_id.split("#")[0]
        return serialize_message(msg)

    resets: list = []
    if args.bad_resets > 0:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from hostile_requests import hostile_requests

        from avp_msgs.srv import ResetEpisode

        client = node.create_client(ResetEpisode, "/avp/reset_episode")
        resets = [ResetEpisode.Request(seed=3, reactive=True, **fields) for fields, _ in hostile_requests().values()]
    reset_sent = 0
    next_reset = time.monotonic()
    sent = {t: dict.fromkeys(kinds, 0) for t in topics}
    print("flooding", flush=True)
    period = 1.0 / args.rate
    t0 = time.monotonic()
    i = 0
    try:
        while not stop["flag"] and time.monotonic() - t0 < args.duration:
            kind = kinds[i % len(kinds)]
            for t in topics:
                data = make(t, kind)
                if data is not None:
                    pubs[t].publish(data)
                    sent[t][kind] += 1
            i += 1
            if resets and time.monotonic() >= next_reset and client.service_is_ready():
                client.call_async(resets[reset_sent % len(resets)])  # the answer is not awaited
                reset_sent += 1
                next_reset += 1.0 / args.bad_resets
            rclpy.spin_once(node, timeout_sec=0.0)
            lag = t0 + i * period - time.monotonic()
            if lag > 0:
                time.sleep(lag)
    except KeyboardInterrupt:
        pass
    wall = time.monotonic() - t0
    total = {t: sum(v.values()) for t, v in sent.items()}
    rates = {t: round(n / wall, 1) for t, n in total.items()}
    print(json.dumps({"wall_s": round(wall, 2), "sent": sent, "bad_resets": reset_sent, "rate_hz": rates}),
          flush=True)
    del subs
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Raw subscriptions that take a burst of queued messages in one executor round (a flood: docs/bad_input.md row 48).

rclpy's executor rebuilds its wait set for every message it takes: about 0.1-0.2 ms of Python per message, which a
publisher gone wild at 1 kHz turns into most of a core in every process that subscribes (measured: the demo's
launcher, which records the graph, used more CPU than the flooder itself). :func:`draining_subscription` handles the
message the executor took, then takes what else is queued on the same reader (up to ``max_batch``) straight from
its handle, in order — one wait-set round per batch instead of per message. Behaviour is unchanged: the same
callback, the same messages, the same order on the topic.
"""

from __future__ import annotations

from collections.abc import Callable

from avp_common.qos import QUIET_READER

#: messages one subscription takes in one executor round
MAX_BATCH = 256


def draining_subscription(node, msg_type, topic: str, callback: Callable, qos, *, with_info: bool = False,
                          max_batch: int = MAX_BATCH):
    """A raw (CDR bytes) subscription calling ``callback(data)`` — or ``callback(data, info)`` with
    ``with_info`` — for every message, taking bursts in one round; returns the rclpy subscription. It has no QoS
    event handlers (:data:`avp_common.qos.QUIET_READER`)."""
    holder: dict = {}

    def first(data, info=None) -> None:
        callback(data, info) if with_info else callback(data)
        sub = holder["sub"]
        for _ in range(max_batch):
            try:
                with sub.handle:
                    taken = sub.handle.take_message(msg_type, True)
            except Exception:  # noqa: BLE001 - destroyed or shutting down: the executor takes it from here
                return
            if taken is None:
                return
            callback(taken[0], taken[1]) if with_info else callback(taken[0])

    if with_info:
        holder["sub"] = node.create_subscription(msg_type, topic, lambda d, i: first(d, i), qos, raw=True,
                                                 event_callbacks=QUIET_READER)
    else:
        holder["sub"] = node.create_subscription(msg_type, topic, lambda d: first(d), qos, raw=True,
                                                 event_callbacks=QUIET_READER)
    return holder["sub"]

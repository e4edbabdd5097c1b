"""Service calls that survive a lost response: re-sent while unanswered, or sent once with their effect watched.

`wait_for_service` returning True means the *client* has matched the server's endpoints; the server may not yet
have matched the client's response reader. Fast DDS then waits 100 ms for that match and otherwise drops the
response (ros2/rmw_fastrtps#390, #467) — on a loaded two-core machine, right after start-up, discovery can take
longer, and a single `call_async` then never completes. For idempotent requests (`reset_episode` with a seed,
`get_state`, `get_parameters`) re-sending is the cure (:func:`call_idempotent`); others (a reset that starts
a running episode, a lifecycle `change_state`) are sent once and their effect is watched for as well
(:func:`call_once`: the new episode's status; the node's lifecycle state, asked every 2 s in ``lifecycle.py``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any


def call_idempotent(client: Any, request: Any, spin_once: Callable[[float], None], timeout: float = 30.0,
                    resend_after: float = 2.0) -> Any | None:
    """Send `request` on `client` (an rclpy Client) and spin with `spin_once(seconds)` until it is answered;
    re-send it every `resend_after` s without an answer. Returns the response, or None after `timeout` s."""
    t0 = time.monotonic()
    while True:
        future = client.call_async(request)
        t_sent = time.monotonic()
        while not future.done():
            now = time.monotonic()
            if now - t0 >= timeout or now - t_sent >= resend_after:
                break
            spin_once(0.05)
        if future.done():
            return future.result()
        client.remove_pending_request(future)
        if time.monotonic() - t0 >= timeout:
            return None


def call_once(client: Any, request: Any, spin_once: Callable[[float], None], effect_seen: Callable[[], bool],
              timeout: float = 30.0) -> Any | None:
    """Send a request that must not be repeated (``reset_episode`` that starts the episode, a lifecycle transition)
    and spin until it is answered or ``effect_seen()`` shows its effect another way (e.g. the new episode's status
    arrived): the answer may have been lost (module docstring). Returns the response, or None when only the effect
    was seen; TimeoutError after ``timeout`` s with neither."""
    future = client.call_async(request)
    t0 = time.monotonic()
    while not future.done():
        if effect_seen():
            spin_once(0.0)  # an answer already received is still taken
            if future.done():
                break
            client.remove_pending_request(future)
            return None
        if time.monotonic() - t0 >= timeout:
            client.remove_pending_request(future)
            raise TimeoutError(f"no answer on {client.srv_name} within {timeout} s")
        spin_once(0.05)
    return future.result()

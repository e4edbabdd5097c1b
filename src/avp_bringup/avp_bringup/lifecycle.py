"""Lifecycle (managed node) service calls and graph queries from a plain rclpy node, as ros2cli's `ros2 lifecycle`
would make them (ros2cli is not on PyPI here). The live planner swap built on them is :mod:`avp_bringup.swap`.
"""

from __future__ import annotations

import time

from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState

from avp_common.services import call_idempotent, call_once

TRANSITIONS = {"configure": Transition.TRANSITION_CONFIGURE, "cleanup": Transition.TRANSITION_CLEANUP,
               "activate": Transition.TRANSITION_ACTIVATE, "deactivate": Transition.TRANSITION_DEACTIVATE,
               "shutdown": None}  # shutdown: the id depends on the current state
#: the state a transition ends in when it succeeds
GOAL_STATE = {"configure": "inactive", "cleanup": "unconfigured", "activate": "active", "deactivate": "inactive",
              "shutdown": "finalized"}
RECHECK_S = 2.0  # s without an answer to change_state before the state is asked instead
SHUTDOWN_FROM = {"unconfigured": Transition.TRANSITION_UNCONFIGURED_SHUTDOWN,
                 "inactive": Transition.TRANSITION_INACTIVE_SHUTDOWN,
                 "active": Transition.TRANSITION_ACTIVE_SHUTDOWN}


class SwapError(RuntimeError):
    """The swap could not be done (the message says which node and why)."""


#: the node name rmw reports for an endpoint whose node has not been discovered yet
UNKNOWN_NODE = "_NODE_NAME_UNKNOWN_"


def fq_name(namespace: str, name: str) -> str:
    return f"{namespace.rstrip('/')}/{name}"


class LifecycleClient:
    """Lifecycle service calls and graph queries from a plain rclpy node (spun while waiting)."""

    def __init__(self, node) -> None:
        self.node = node
        self._clients: dict[tuple[str, str], object] = {}

    def _client(self, target: str, kind: str):
        key = (target, kind)
        if key not in self._clients:
            srv = GetState if kind == "get_state" else ChangeState
            self._clients[key] = self.node.create_client(srv, f"{target}/{kind}")
        return self._clients[key]

    def _ready(self, target: str, kind: str, timeout: float):
        client = self._client(target, kind)
        if not client.wait_for_service(timeout_sec=timeout):
            raise SwapError(f"{target}: no lifecycle service {target}/{kind} (not running, or not a lifecycle node)")
        return client

    def _spin_once(self, seconds: float) -> None:
        import rclpy

        rclpy.spin_once(self.node, timeout_sec=seconds)

    def state(self, target: str, timeout: float = 10.0) -> str:
        """The lifecycle state's label; get_state is safe to repeat, so it is re-sent while unanswered (a response
        can be lost while discovery settles: avp_common/services.py)."""
        res = call_idempotent(self._ready(target, "get_state", timeout), GetState.Request(), self._spin_once, timeout)
        if res is None:
            raise SwapError(f"{target}: get_state did not answer within {timeout} s")
        return res.current_state.label

    def change(self, target: str, transition: str, timeout: float = 30.0) -> None:
        """Request ``transition``. A transition must not be sent twice, so while its answer is missing the node's
        state is asked every RECHECK_S s: reaching the transition's goal state counts as its answer."""
        tid = TRANSITIONS[transition]
        if transition == "shutdown":
            tid = SHUTDOWN_FROM.get(self.state(target, timeout))
            if tid is None:
                return  # finalized already
        req = ChangeState.Request()
        req.transition.id = tid
        client = self._ready(target, "change_state", timeout)
        next_check = [time.monotonic() + RECHECK_S]

        def goal_reached() -> bool:  # asked every RECHECK_S s while the answer is missing
            if time.monotonic() < next_check[0]:
                return False
            try:
                reached = self.state(target, RECHECK_S) == GOAL_STATE[transition]
            except SwapError:  # no answer either; after a shutdown the node may be gone
                reached = transition == "shutdown" and not self._client(target, "get_state").service_is_ready()
            next_check[0] = time.monotonic() + RECHECK_S
            return reached

        try:
            res = call_once(client, req, self._spin_once, goal_reached, timeout)
        except TimeoutError:
            raise SwapError(f"{target}: change_state '{transition}' did not answer within {timeout} s") from None
        if res is not None and not res.success:
            raise SwapError(f"{target}: transition '{transition}' failed (state {self.state(target, timeout)})")

    def parameters(self, target: str, names: tuple[str, ...], timeout: float = 5.0) -> dict:
        """The values of ``names`` that ``target`` has declared (rcl_interfaces GetParameters); {} when the node
        has no parameter service or does not answer in time."""
        from rcl_interfaces.msg import ParameterType
        from rcl_interfaces.srv import GetParameters

        key = (target, "get_parameters")
        if key not in self._clients:
            self._clients[key] = self.node.create_client(GetParameters, f"{target}/get_parameters")
        client = self._clients[key]
        if not client.wait_for_service(timeout_sec=timeout):
            return {}
        res = call_idempotent(client, GetParameters.Request(names=list(names)), self._spin_once, timeout)
        if res is None:
            return {}
        readers = {ParameterType.PARAMETER_BOOL: "bool_value", ParameterType.PARAMETER_INTEGER: "integer_value",
                   ParameterType.PARAMETER_DOUBLE: "double_value", ParameterType.PARAMETER_STRING: "string_value"}
        return {n: getattr(v, readers[v.type]) for n, v in zip(names, res.values, strict=False)
                if v.type in readers}

    def spin(self, seconds: float) -> None:
        import rclpy

        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds:
            rclpy.spin_once(self.node, timeout_sec=0.05)

    def is_lifecycle(self, target: str) -> bool:
        return any(name == f"{target}/get_state" for name, _ in self.node.get_service_names_and_types())

    def cmd_publishers(self, namespace: str, wait: float = 3.0) -> list[str]:
        """Fully qualified names of the nodes publishing on ``<namespace>/cmd`` (the planners).

        DDS can discover a publisher before the node that owns it: rmw then names the node
        ``_NODE_NAME_UNKNOWN_``. Such names are waited for (up to ``wait`` s of discovery) rather than returned
        as a node that is not there; after that they are returned as they are."""
        t0 = time.monotonic()
        while True:
            infos = self.node.get_publishers_info_by_topic(f"{namespace.rstrip('/')}/cmd")
            names = sorted({fq_name(i.node_namespace, i.node_name) for i in infos})
            if not any(UNKNOWN_NODE in n for n in names) or time.monotonic() - t0 > wait:
                return names
            self.spin(0.1)

    def planners(self, namespace: str, wait: float = 0.0, exclude: str = "") -> list[str]:
        """:meth:`cmd_publishers` of ``namespace`` other than ``exclude``, waited for up to ``wait`` s of discovery
        until there is one (a fresh process on a loaded machine may not have discovered them yet)."""
        t0 = time.monotonic()
        while True:
            names = [n for n in self.cmd_publishers(namespace) if n != exclude]
            if names or time.monotonic() - t0 >= wait:
                return names
            self.spin(0.1)

    def observation_topic(self, target: str, wait: float = 3.0) -> str | None:
        """The topic from which the node ``target`` (fully qualified) reads its avp_msgs/Observation, if it has one
        subscription of that type; DDS may name a node's subscriptions later than its publishers, so they are
        waited for up to ``wait`` s."""
        ns, _, name = target.rpartition("/")
        t0 = time.monotonic()
        while True:
            try:
                subs = self.node.get_subscriber_names_and_types_by_node(name, ns or "/")
            except Exception:  # noqa: BLE001 - rclpy raises for a node it does not know (yet)
                subs = []
            topics = [t for t, types in subs if "avp_msgs/msg/Observation" in types]
            if topics or time.monotonic() - t0 > wait:
                return topics[0] if len(topics) == 1 else None
            self.spin(0.1)

    def lifecycle_nodes(self, namespace: str) -> list[str]:
        ns = namespace.rstrip("/")
        return sorted(n[: -len("/get_state")] for n, t in self.node.get_service_names_and_types()
                      if n.startswith(ns + "/") and n.endswith("/get_state") and "lifecycle_msgs/srv/GetState" in t)


def shutdown_lifecycle_nodes(namespace: str = "/avp", discovery: float = 1.0, timeout: float = 5.0) -> list[str]:
    """Shut down every lifecycle node of ``namespace`` (e.g. planners swapped in by another process)."""
    import rclpy

    own = not rclpy.ok()
    if own:
        rclpy.init()
    node = rclpy.create_node("avp_lifecycle_shutdown")
    done = []
    try:
        client = LifecycleClient(node)
        client.spin(discovery)
        for n in client.lifecycle_nodes(namespace):
            try:
                client.change(n, "shutdown", timeout)
                done.append(n)
            except SwapError:
                pass
    finally:
        node.destroy_node()
        if own:
            rclpy.try_shutdown()
    return done

"""Lifecycle (managed) node helpers shared by the swappable planner nodes."""

from __future__ import annotations

from rclpy.lifecycle import LifecycleNode


def guard_lifecycle_services(node: LifecycleNode) -> None:
    """Answer an invalid transition request (e.g. activate while unconfigured) with success = false and
    one log line instead of letting rclpy's exception end the node."""
    srv = node._service_change_state
    inner = srv.callback

    def callback(req, resp):
        try:
            return inner(req, resp)
        except Exception as exc:  # noqa: BLE001 - a bad request must not end the node
            state = node._state_machine.current_state[1]
            node.get_logger().error(f"change_state: transition {req.transition.id} "
                                    f"'{req.transition.label}' is not possible from state '{state}' ({exc})")
            resp.success = False
            return resp

    srv.callback = callback

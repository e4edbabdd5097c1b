"""The shared ``main()`` of every AVP node: init, spin, one-line start-up errors, clean shutdown."""

from __future__ import annotations

import sys
from collections.abc import Callable

import rclpy
from rclpy.executors import ExternalShutdownException

from avp_common.params import ParameterError


def ctrl_c_in_finaliser_hook(unraisable) -> None:
    """``sys.unraisablehook`` of a node process: a Ctrl-C whose KeyboardInterrupt lands in a finaliser
    (``__del__``) is swallowed by Python — rclpy's SIGINT handler has shut the context down, and the node exits
    through :func:`run_node`; nothing to print. Anything else goes to the default hook."""
    if isinstance(unraisable.exc_value, KeyboardInterrupt):
        return
    sys.__unraisablehook__(unraisable)


def run_node(factory: Callable[[], object], label: str, args=None) -> int:
    """Build the node with ``factory`` and spin it. A bad parameter/map at start-up prints one line
    (``[label] start-up failed: ...``) and returns 2; Ctrl-C / external shutdown return 0 (also when rclpy raises
    because the context is already shut down); any other error propagates."""
    rclpy.init(args=args)
    node = None
    hook, sys.unraisablehook = sys.unraisablehook, ctrl_c_in_finaliser_hook
    try:
        node = factory()
        rclpy.spin(node)
    except (ParameterError, ValueError) as exc:
        print(f"[{label}] start-up failed: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        # Ctrl-C whose KeyboardInterrupt was swallowed (raised inside a __del__) after rclpy's SIGINT handler had
        # shut the context down: the executor's next wait set fails with RCLError. That is a shutdown, not a fault.
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        sys.unraisablehook = hook
    return 0

"""The shared ``main()`` of every AVP node: init, spin, one-line start-up errors, clean shutdown."""

from __future__ import annotations

import gc
import signal
import sys
from collections.abc import Callable

import rclpy
from rclpy.executors import ExternalShutdownException

from avp_common.lifetime import end_with_starter
from avp_common.params import ParameterError

_stopping = {"signal": 0}  # the signal (SIGINT / SIGTERM) that asked this process to stop, 0 before one came


def _half_built_rclpy_object(unraisable) -> bool:
    """True for an AttributeError in the finaliser of an rclpy object: the KeyboardInterrupt of a stop landed inside
    its ``__init__`` (e.g. ``rclpy.task.Task`` before ``_exception`` was set, seen under a 1 kHz flood), so its
    ``__del__`` reads an attribute that was never assigned."""
    finaliser = unraisable.object
    module = getattr(finaliser, "__module__", "") or ""
    return (isinstance(unraisable.exc_value, AttributeError) and module.split(".")[0] == "rclpy"
            and getattr(finaliser, "__name__", "") == "__del__")


def ctrl_c_in_finaliser_hook(unraisable) -> None:
    """``sys.unraisablehook`` of a node process: a Ctrl-C whose KeyboardInterrupt lands in a finaliser
    (``__del__``) is swallowed by Python — rclpy's SIGINT handler has shut the context down, and the node exits
    through :func:`run_node`; nothing to print. So is, once SIGINT/SIGTERM came, the finaliser of an rclpy object
    whose construction that KeyboardInterrupt cut short. Anything else goes to the default hook."""
    if isinstance(unraisable.exc_value, KeyboardInterrupt):
        return
    if stopping() and _half_built_rclpy_object(unraisable):
        return
    sys.__unraisablehook__(unraisable)


def _mark_stopping(signum: int, frame) -> None:  # noqa: ANN001 - the signal module's signature
    """Python-level SIGINT/SIGTERM handler: remember that a stop was asked for, then stop as before."""
    _stopping["signal"] = signum
    raise KeyboardInterrupt


def stopping() -> bool:
    """True once SIGINT or SIGTERM reached this process (what fails after it is part of the shutdown)."""
    return bool(_stopping["signal"])


def freeze_start_up_heap() -> None:
    """Keep Python's cyclic garbage collector off what exists once a node process has started: collect the start-up's
    garbage, then :func:`gc.freeze` the rest (torch, the lot, the Reeds-Shepp table, the node: long-lived objects that
    a full collection would traverse every time). Objects made afterwards are collected as before. Measured on the busy
    lot, two live egos (docs/benchmarks.md, "The live fleet's relays in real time, garbage collection"): an ego
    pipeline's full (generation 2) collections took up to 232 ms each, 11 a minute, about 2 s in all, one pipeline held
    still each time; frozen, at most 43 ms."""
    gc.collect()
    gc.freeze()


def install_stop_handlers() -> None:
    """SIGINT/SIGTERM mark the process as stopping (:func:`stopping`) and raise KeyboardInterrupt; call before
    ``rclpy.init``, whose C handler chains to these."""
    signal.signal(signal.SIGINT, _mark_stopping)
    signal.signal(signal.SIGTERM, _mark_stopping)


def run_node(factory: Callable[[], object], label: str, args=None) -> int:
    """Build the node with ``factory`` and spin it. A bad parameter/map at start-up prints one line
    (``[label] start-up failed: ...``) and returns 2; Ctrl-C / external shutdown return 0 (also when rclpy raises
    because the context is already shut down); any other error propagates."""
    # installed before rclpy.init, whose C handler (context shut down, executors woken) chains to this one: a take
    # or wait that fails in the window before the KeyboardInterrupt lands (a pybind11 RuntimeError from
    # take_message under a flood, docs/bad_input.md row 53) is then known to be part of the stop, not a fault
    install_stop_handlers()
    end_with_starter()  # SIGTERM when the graph's launcher ends, however it ended (avp_common.lifetime)
    rclpy.init(args=args)
    node = None
    hook, sys.unraisablehook = sys.unraisablehook, ctrl_c_in_finaliser_hook
    try:
        node = factory()
        freeze_start_up_heap()
        rclpy.spin(node)
    except (ParameterError, ValueError) as exc:
        print(f"[{label}] start-up failed: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        # Ctrl-C whose KeyboardInterrupt was swallowed (raised inside a __del__) after rclpy's SIGINT handler had
        # shut the context down: the executor's next wait set fails with RCLError. That is a shutdown, not a fault;
        # so is any error after SIGINT/SIGTERM came (e.g. a take interrupted under a flood).
        if rclpy.ok() and not stopping():
            raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        sys.unraisablehook = hook
    return 0

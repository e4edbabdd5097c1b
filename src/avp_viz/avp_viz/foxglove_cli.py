"""``--foxglove`` of ``avp launch`` and ``avp demo``: the options, and the bridge they start
(:mod:`avp_viz.foxglove_bridge`, imported only when asked for: it loads the message types)."""

from __future__ import annotations

DEFAULT_PORT = 8765


def add_arguments(p) -> None:
    """``--foxglove``, ``--foxglove-port``, ``--foxglove-host`` of ``avp launch`` and ``avp demo``."""
    p.add_argument("--foxglove", action="store_true",
                   help="serve the graph live to Foxglove over its WebSocket protocol (foxglove-sdk; docs/foxglove.md)")
    p.add_argument("--foxglove-port", type=int, default=DEFAULT_PORT, help="its port [8765]")
    p.add_argument("--foxglove-host", default="127.0.0.1",
                   help="the address it binds [127.0.0.1: this machine only; 0.0.0.0 opens it to the network]")


def start(args, drive: bool = False, egos: int = 1):
    """The bridge of ``args`` (``--foxglove``), or None; prints where to connect. ``drive``: the graph has driven
    cars, which Foxglove's Teleop panel may drive (avp_viz.foxglove_drive)."""
    if not getattr(args, "foxglove", False):
        return None
    from avp_viz.foxglove_bridge import FoxgloveBridge, view_topics

    bridge = FoxgloveBridge(args.foxglove_port, args.foxglove_host, topics=view_topics(egos), drive=drive)
    print(f"[avp] Foxglove: connect to ws://{args.foxglove_host}:{bridge.port} (layout: docs/foxglove_layout.json)",
          flush=True)
    return bridge

"""Plugins the ROS way in Python: Python entry-point groups, the counterpart of ROS's pluginlib (ROS-free).

A kind of plugin (trajectory predictors: ``avp.predictors``; spot selectors: ``avp.spot_selectors``) has
built-in names mapped to ``"package.module:Class"`` and takes more from the entry points installed in the
environment. A plugin cannot replace a built-in name; an unknown name gets one error listing every name.
"""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points


def available(group: str, builtins: dict[str, str]) -> dict[str, str]:
    """Every ``name -> "module:Class"`` of the kind: the built-ins, then the plugins of entry-point ``group``."""
    out = dict(builtins)
    for ep in entry_points(group=group):
        out.setdefault(ep.name, ep.value)
    return out


def load_class(group: str, builtins: dict[str, str], name: str, kind: str, doc: str) -> type:
    """The class registered as ``name``; ValueError naming the ``kind``, every known name, the group and ``doc``
    (the page that explains the plugin interface) when it is unknown or cannot be imported."""
    known = builtins if name in builtins else available(group, builtins)  # built-ins: no entry-point scan
    if name not in known:
        raise ValueError(f"unknown {kind} {name!r}; choose one of {sorted(known)} (plugins: entry-point group "
                         f"{group!r}, {doc})")
    module, _, attr = known[name].partition(":")
    try:
        return getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"{kind} {name!r}: cannot load {known[name]!r} ({type(exc).__name__}: {exc})") from None

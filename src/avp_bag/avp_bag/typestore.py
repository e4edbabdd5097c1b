"""The message types of a bag: ROS 2 Jazzy's plus every avp_msgs message, for `rosbags` (writing, reading) and
the Python message classes of the installed packages (replay, the Foxglove bridge)."""

from __future__ import annotations

import importlib
from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from rosbags.typesys import Stores, get_types_from_msg, get_typestore


def make_typestore():
    """ROS 2 Jazzy types plus every avp_msgs message (from the installed .msg files)."""
    ts = get_typestore(Stores.ROS2_JAZZY)
    share = Path(get_package_share_directory("avp_msgs")) / "msg"
    types = {}
    for f in sorted(share.glob("*.msg")):
        types.update(get_types_from_msg(f.read_text(), f"avp_msgs/msg/{f.stem}"))
    ts.register(types)
    return ts


def message_class(typename: str):
    pkg, kind, name = typename.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), name)

"""The message types of a bag: ROS 2 Jazzy's plus every avp_msgs message, for `rosbags` (writing, reading) and
the Python message classes of the installed packages (replay, the Foxglove bridge)."""

from __future__ import annotations

import importlib
from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

#: the message packages of our own graph beyond ROS 2 Jazzy's (autoware_perception_msgs: the tracker's input and
#: output, vendor/ where Autoware is absent)
BAG_PACKAGES = ("avp_msgs", "autoware_perception_msgs")


def make_typestore():
    """ROS 2 Jazzy types plus every message of :data:`BAG_PACKAGES` (from the installed .msg files)."""
    ts = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for pkg in BAG_PACKAGES:
        share = Path(get_package_share_directory(pkg)) / "msg"
        for f in sorted(share.glob("*.msg")):
            types.update(get_types_from_msg(f.read_text(), f"{pkg}/msg/{f.stem}"))
    ts.register(types)
    return ts


def message_class(typename: str):
    pkg, kind, name = typename.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), name)

"""Where a package's shipped files (``config/``) are: its ament share directory in a sourced workspace, else its
folder in the source tree (the ROS-free cores run from a checkout too, e.g. the in-process experiment runner on a
machine without ROS)."""

from __future__ import annotations

from pathlib import Path

SRC = Path(__file__).resolve().parents[2]  # src/ (the install tree links back here: --symlink-install)


def package_share(package: str) -> Path:
    """``share/<package>`` of the sourced workspace, else ``src/<package>``."""
    try:
        from ament_index_python.packages import get_package_share_directory

        return Path(get_package_share_directory(package))
    except Exception:  # noqa: BLE001 - no ament index (not sourced, or no ROS here): the source tree
        return SRC / package

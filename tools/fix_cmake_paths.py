"""Rewrite the wheel-build container's Python paths in the venv's exported CMake files.

The ros-jazzy-* message wheels were built under /opt/python/cp311-cp311 and their exported CMake
targets name that interpreter's include dir and site-packages. Without this rewrite `colcon build`
of an interface package fails to find Python.h / the generator modules (docs/install.md, fix 1).
"""

from __future__ import annotations

import sys
import sysconfig
from pathlib import Path

OLD_INCLUDE = "/opt/python/cp311-cp311/include/python3.11"
OLD_SITE = "/opt/python/cp311-cp311/lib/python3.11/site-packages"


def main(venv: str) -> int:
    venv_path = Path(venv).resolve()
    include = sysconfig.get_paths()["include"]
    site = sysconfig.get_paths()["purelib"]
    changed = 0
    for path in (venv_path / "share").rglob("*.cmake"):
        text = path.read_text(errors="surrogateescape")
        new = text.replace(OLD_INCLUDE, include).replace(OLD_SITE, site)
        if new != text:
            path.write_text(new, errors="surrogateescape")
            changed += 1
    print(f"[bootstrap] rewrote Python paths in {changed} CMake files")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else sys.prefix))

"""Which process launched the graph of a ROS domain: a small JSON file that a :class:`~avp_bringup.graph.Graph`
writes when it starts and removes when it stops, beside the domain's lock file (avp_bringup.domain:
``<tmp>/avp-domains-<uid>/<ROS_DOMAIN_ID>.launcher.json``; written also where the environment chose the domain).

``avp swap-planner`` reads it so that the planner it starts ends with the graph it joined (the launcher's end)
rather than with the swap command (docs/architecture.md, "Processes"). A file whose launcher has ended (killed
before it could remove it) names nobody.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from avp_common.lifetime import alive, start_time


def launcher_path(env: dict | None = None) -> Path:
    """The file of the ROS domain that ``env`` (default: this process's environment) selects."""
    from avp_bringup.domain import lock_dir

    env = os.environ if env is None else env
    domain = (env.get("ROS_DOMAIN_ID") or "0").strip() or "0"
    return lock_dir() / f"{domain}.launcher.json"


def write_launcher(env: dict | None = None, pid: int | None = None) -> Path:
    """Record process ``pid`` (default: this one) as the launcher of the domain's graph; returns the file."""
    pid = os.getpid() if pid is None else int(pid)
    path = launcher_path(env)
    tmp = path.with_suffix(f".{pid}.tmp")
    tmp.write_text(json.dumps({"pid": pid, "start": start_time(pid)}))
    os.replace(tmp, path)
    return path


def read_launcher(env: dict | None = None) -> int | None:
    """The pid of the running launcher of the domain's graph, or None (no file, an unreadable one, or a launcher
    that has ended)."""
    try:
        data = json.loads(launcher_path(env).read_text())
        pid, start = int(data["pid"]), str(data.get("start", ""))
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return pid if pid > 0 and alive(pid, start) else None


def remove_launcher(env: dict | None = None, pid: int | None = None) -> None:
    """Remove the domain's file if it names process ``pid`` (default: this one)."""
    pid = os.getpid() if pid is None else int(pid)
    path = launcher_path(env)
    try:
        if int(json.loads(path.read_text())["pid"]) == pid:
            path.unlink()
    except (OSError, ValueError, KeyError, TypeError):
        pass

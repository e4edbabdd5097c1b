"""An isolated DDS domain per graph on one machine (two demos at once must not cross-talk; docs/bad_input.md row 38).

``avp launch`` / ``avp demo`` / ``avp experiment --transport ros`` claim a ROS_DOMAIN_ID of their own unless the
environment sets one (the override): the first of 1..:data:`MAX_DOMAIN` whose lock file
(``<tmp>/avp-domains-<uid>/<id>.lock``) no running avp graph holds (``flock``, released when the process ends,
also on SIGKILL). Domain 0, everyone's default, is never claimed. Tools that talk to a running graph
(``avp swap-planner``, ``avp record``, ``avp replay``) without ROS_DOMAIN_ID join the domain of the one graph
that holds a lock (and ask for ROS_DOMAIN_ID when several do). Discovery stays on localhost
(:class:`avp_bringup.graph.Graph`), so graphs on other hosts are not seen either.
"""

from __future__ import annotations

import fcntl
import os
import tempfile
from pathlib import Path
from typing import IO

MAX_DOMAIN = 101  # Fast DDS's port arithmetic allows 0..232; keep to the range every RMW accepts
_HELD: list[IO] = []  # lock files of this process (kept open for its lifetime)


def lock_dir() -> Path:
    d = Path(tempfile.gettempdir()) / f"avp-domains-{os.getuid()}"
    d.mkdir(mode=0o700, exist_ok=True)
    return d


def _try_lock(domain: int) -> IO | None:
    f = open(lock_dir() / f"{domain}.lock", "a+")  # noqa: SIM115 - held for the process's lifetime
    try:
        fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        f.close()
        return None
    f.seek(0)
    f.truncate()
    f.write(f"{os.getpid()}\n")
    f.flush()
    return f


def claim_domain(environ: dict | None = None) -> tuple[int, bool]:
    """Set ROS_DOMAIN_ID in ``environ`` (default ``os.environ``) for a new graph: (id, claimed) — claimed False
    when the environment chose it already. RuntimeError if every domain is held."""
    env = os.environ if environ is None else environ
    if env.get("ROS_DOMAIN_ID", "").strip():
        return int(env["ROS_DOMAIN_ID"]), False
    for d in range(1, MAX_DOMAIN + 1):
        f = _try_lock(d)
        if f is not None:
            _HELD.append(f)
            env["ROS_DOMAIN_ID"] = str(d)
            return d, True
    raise RuntimeError(f"every ROS domain 1..{MAX_DOMAIN} is held by a running avp graph ({lock_dir()})")


def running_domains() -> list[int]:
    """Domains whose lock a running avp graph holds."""
    out = []
    for p in sorted(lock_dir().glob("*.lock"), key=lambda q: int(q.stem) if q.stem.isdigit() else -1):
        if not p.stem.isdigit():
            continue
        f = _try_lock(int(p.stem))
        if f is None:
            out.append(int(p.stem))
        else:
            fcntl.flock(f, fcntl.LOCK_UN)
            f.close()
    return out


def join_running_domain(environ: dict | None = None) -> int | None:
    """For tools that talk to a running graph: keep ROS_DOMAIN_ID if set, else take the one running graph's
    domain (None if there is none); ValueError naming them if several run."""
    env = os.environ if environ is None else environ
    if env.get("ROS_DOMAIN_ID", "").strip():
        return int(env["ROS_DOMAIN_ID"])
    running = running_domains()
    if len(running) > 1:
        raise ValueError(f"several avp graphs are running (ROS_DOMAIN_ID {running}); set ROS_DOMAIN_ID to choose")
    if running:
        env["ROS_DOMAIN_ID"] = str(running[0])
        return running[0]
    return None

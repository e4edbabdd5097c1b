"""Mechanism c (docs/experiment.md) — waiting anywhere on the path (``decision.wait_anywhere``; off = the paper).

§V-D-1 prices a Hybrid A* path with its speed profile and, if it meets a predicted agent, tries starting it after
a wait (Nawaz et al.'s wait-and-go, 0 .. ``max_wait``): the ego can only wait where it stands. Here, when every
start wait fails, the ego may instead drive part of the path, stop ``wait_stop_offsets`` metres (arc length) short
of where it would first meet an agent, stand there 0 .. ``max_wait`` and go on — a station-time profile with one
stop, the coarse form of a speed plan over a space-time grid (Apollo's). The stop is an extra piece end of the
path (:attr:`avp_search.paths.Path.stops`): the speed profile brakes to rest there at a_max, as at a cusp. The whole
profile, waiting included, is checked against every prediction as before.
"""

from __future__ import annotations

import numpy as np

from avp_motion.control import reference_trajectory
from avp_search.paths import Path


def stop_index(speeds: np.ndarray, dt: float, arc: float) -> int:
    """Index of the stop control (zero speed) of a reference profile nearest to arc length ``arc``."""
    s = np.cumsum(np.abs(speeds)) * dt
    zero = np.nonzero(np.abs(speeds) < 1e-12)[0]
    return int(zero[np.argmin(np.abs(s[zero] - arc))])


def insert_wait(states: np.ndarray, controls: np.ndarray | None, at: int, wait: int):
    """Stand ``wait`` more steps after control ``at`` (a stop): states (T + 1, ...) and controls (T, 2) or None."""
    st = np.concatenate([states[: at + 2], np.repeat(states[at + 1: at + 2], wait, axis=0), states[at + 2:]])
    if controls is None:
        return st, None
    return st, np.concatenate([controls[: at + 1], np.zeros((wait, controls.shape[1])), controls[at + 1:]])


def stop_and_wait(path: Path, speeds: np.ndarray, first_hit: int, dyn, control, decision,
                  v0: float) -> tuple[Path, int, np.ndarray] | None:
    """The quickest (path with one stop, steps waited there, ego poses) that meets no prediction, trying the waits
    0, wait_step, .. max_wait at each stop offset; None if none does (module docstring)."""
    dt = control.dt
    arc = np.concatenate([[0.0], np.cumsum(np.abs(speeds)) * dt])
    hit_arc = float(arc[min(first_hit, len(arc) - 1)])
    stops = [hit_arc - off for off in decision.wait_stop_offsets if 0.3 < hit_arc - off < path.length - 0.3]
    if not stops:
        return None
    profiles = []
    for s in stops:
        p = Path(path.start, path.segments, (s,))
        pp, sp = reference_trajectory(p, control, v0)
        profiles.append((p, pp, stop_index(sp, dt, s)))
    step = max(1, int(round(decision.wait_step / dt)))
    for w in range(0, int(round(decision.max_wait / dt)) + 1, step):
        for p, pp, at in profiles:
            ego, _ = insert_wait(pp, None, at, w)
            if dyn.first_collision(ego) < 0:
                return p, w, ego
    return None

"""A moving vehicle track's recent history smoothed by the filter (``tracking.history_smoothing`` rts;
docs/perception.md, "The tracker").

The ego reads a car's motion from the last poses of its history (the Bézier fit, avp_motion's yield rule and trace:
speed from two successive poses). Through the tracker those are the filter's successive estimates, and each step's
correction jump reads as a change of speed: a car at a steady 2 m/s detected with 0.1 m noise reads as braking in
about a quarter of the steps (tools/motion_from_tracks.py). A fixed-lag Rauch-Tung-Striebel smoother replaces the
last ``lag`` poses with the estimates given every detection up to now: the last pose is the filter's own, the earlier
ones agree with the velocities the filter has since learned. A stationary (held) track keeps its held history.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from avp_tracking.core.motion import wrap


@dataclass
class FilterStep:
    """One step of a vehicle track's filter: the estimate after the step (x, P) and the prediction from it to the
    next step (F, x_next, P_next; None until that step comes)."""

    step: int
    x: np.ndarray
    P: np.ndarray
    F: np.ndarray | None = None
    x_next: np.ndarray | None = None
    P_next: np.ndarray | None = None


def remember(steps: deque, step: int, x: np.ndarray, P: np.ndarray, lag: int) -> None:
    """Append this step's estimate; keep ``lag`` steps."""
    steps.append(FilterStep(step, x.copy(), P.copy()))
    while len(steps) > lag:
        steps.popleft()


def smoothed_poses(steps: deque) -> list[tuple[int, np.ndarray]]:
    """(step, smoothed pose (3,)) of each remembered step, oldest first: the RTS backward pass
    x_s[k] = x[k] + C (x_s[k+1] - x_next[k]), C = P[k] F^T P_next[k]^-1, over the steps linked by predictions."""
    items = list(steps)
    if not items:
        return []
    xs = items[-1].x.copy()
    out = [(items[-1].step, xs[:3].copy())]
    for k in range(len(items) - 2, -1, -1):
        it = items[k]
        if it.F is None or it.x_next is None or it.P_next is None:
            break  # no prediction links it to the next step (a reset): older steps stay as they were
        C = np.linalg.solve(it.P_next.T, (it.P @ it.F.T).T).T  # P F^T P_next^-1
        d = xs - it.x_next
        d[2] = wrap(float(d[2]))
        xs = it.x + C @ d
        xs[2] = wrap(float(xs[2]))
        out.append((it.step, xs[:3].copy()))
    return out[::-1]


def history_smoothed(history: deque, steps: deque) -> np.ndarray:
    """(H, 3) the history with the poses of the remembered steps replaced by their smoothed ones."""
    fixed = dict(smoothed_poses(steps))
    return np.array([fixed.get(s, p) for s, p in history], dtype=float).reshape(-1, 3)

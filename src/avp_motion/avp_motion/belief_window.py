"""A vacant spot's belief read over its last steps (``decision.belief_window``; beyond the paper).

§V-D-1 takes the candidate spots I_can,0 = {i in I_vac,t : b_t,i <= δ} from this step's belief, and the static
world draws every spot with b_t,i >= β as an obstacle. On an observed vacant spot b_t,i is eq. (8)'s, made of this
step's intentions alone. With the paper's exact sensing an intention moves smoothly. Behind a tracker it can jump for
a step: a parked car newly seen gets a young track whose speed reads 1.4 m/s, is given as dynamic, and the intent CNN
sends it into the spot beside it with 0.98 (docs/research/sensing_noise.md, busy DLP seed 112). The planner then
drops its plan to that spot ("static obstacle on the plan") and leaves for another spot, to come back a step later.

With a window of n steps the planner reads an observed vacant spot's belief as the lower median of its eq. (8)
values over the last n steps in which it was observed vacant without a break (fewer while the run is younger): a
spike shorter than half the window is not seen, and an intention that stays is seen (n - 1) // 2 steps late (the
lower median takes the first value of a new run at once, so a spot newly seen vacant is read as the paper reads it).
Spots not observed vacant this step keep b_t,i (eq. 7 makes them 1 when observed occupied). n = 1 is the paper.
"""

from __future__ import annotations

import numpy as np


class BeliefWindow:
    """The last ``steps`` eq. (8) values of each spot while it is observed vacant without a break."""

    def __init__(self, n_spots: int, steps: int):
        if steps < 1:
            raise ValueError(f"belief window must be >= 1 step, got {steps}")
        self.steps = int(steps)
        self._values = np.full((self.steps, n_spots), np.nan)  # rows: the last steps, newest at _head
        self._head = -1

    def clear(self) -> None:
        self._values[:] = np.nan
        self._head = -1

    def read(self, beliefs: np.ndarray, vacant_rows: np.ndarray) -> np.ndarray:
        """b_t as the planner reads it this step: on ``vacant_rows`` (I_vac,t) the lower median of the spot's
        values over its current run of vacant steps (this one included), elsewhere ``beliefs``. Call once per step."""
        b = np.asarray(beliefs, dtype=float)
        if self.steps == 1:
            return b
        vac = np.zeros(len(b), dtype=bool)
        vac[np.asarray(vacant_rows, dtype=np.int64)] = True
        self._head = (self._head + 1) % self.steps
        self._values[:, ~vac] = np.nan  # a break ends the run
        self._values[self._head, vac] = b[vac]
        out = b.copy()
        cols = np.flatnonzero(vac)
        if len(cols):
            window = np.sort(self._values[:, cols], axis=0)  # nan sorts last
            n = np.sum(~np.isnan(window), axis=0)
            out[cols] = window[(n - 1) // 2, np.arange(len(cols))]
        return out

"""One ego's closed-loop step time (sense → command), as :mod:`avp_monitor.monitor` defines it: for every step k,
the DDS source timestamp of observation k (the simulator's writer; in lock-step, its last re-send before the answer)
to the DDS reception timestamp of the first command stamped t_k at the monitor's reader. The monitor keeps one per
ego (``observation``/``cmd`` with one ego, ``ego<i>/observation``/``ego<i>/cmd`` with several)."""

from __future__ import annotations

import numpy as np

from avp_common.qos import RESEND_ANSWER_INTERVAL


class StepTimer:
    """What the step time of one ego is computed from (stamps and timestamps in ns, the system clock)."""

    def __init__(self) -> None:
        self.obs_sent: dict[int, list[int]] = {}  # stamp -> DDS source timestamps of the observation
        self.next_sent: dict[int, int] = {}  # stamp -> source timestamp of the observation after it
        self.cmd_received: dict[int, int] = {}  # stamp -> reception timestamp of the first command
        self._last_stamp: int | None = None

    def on_obs(self, stamp: int, sent: int) -> bool:
        """An observation stamped ``stamp`` sent at ``sent``; False when it is an older step's stale copy, a duplicate
        or a re-send (not a new step). An earlier stamp after a later one starts a new episode: the time restarts."""
        if self._last_stamp is not None and 0 < stamp < self._last_stamp:
            return False  # an older step (a stale copy): not a new episode
        if self.restarts(stamp):  # a new episode: time restarts at 0
            self.clear()
        earlier = self.obs_sent.setdefault(stamp, [])
        if earlier and sent - earlier[-1] < RESEND_ANSWER_INTERVAL * 1e9:
            return False  # a copy (duplicate delivery, or replayed by another process), not a re-send
        earlier.append(sent)  # more than one: re-sent in lock-step
        if self._last_stamp is not None and self._last_stamp < stamp:
            self.next_sent.setdefault(self._last_stamp, sent)
        self._last_stamp = stamp
        return True

    def restarts(self, stamp: int) -> bool:
        """Whether an observation stamped ``stamp`` starts a new episode (time back at 0 after a later step)."""
        return self._last_stamp is not None and stamp < self._last_stamp and stamp <= 0

    def on_cmd(self, stamp: int, received: int) -> None:
        self.cmd_received.setdefault(stamp, received)

    def clear(self) -> None:
        for d in (self.obs_sent, self.next_sent, self.cmd_received):
            d.clear()
        self._last_stamp = None

    def step_times(self) -> tuple[np.ndarray, int]:
        """(closed-loop step times [s] of the steps answered, in step order; how many answers came after the next
        observation had been sent)."""
        stamps = sorted(k for k in self.obs_sent if k in self.cmd_received)
        # the send the command answers: the last one before it arrived
        sent = {k: max([t for t in self.obs_sent[k] if t <= self.cmd_received[k]] or self.obs_sent[k][:1])
                for k in stamps}
        lat = np.array([(self.cmd_received[k] - sent[k]) * 1e-9 for k in stamps])
        late = sum(1 for k in stamps if k in self.next_sent and self.cmd_received[k] > self.next_sent[k])
        return lat, late


def summary_ms(lat: np.ndarray) -> dict:
    """Median, p95, mean, max and min [ms] of step times [s] (empty: nothing)."""
    ms = np.asarray(lat) * 1e3
    if not len(ms):
        return {}
    return {"median_ms": round(float(np.median(ms)), 2), "p95_ms": round(float(np.percentile(ms, 95)), 2),
            "mean_ms": round(float(ms.mean()), 2), "max_ms": round(float(ms.max()), 2),
            "min_ms": round(float(ms.min()), 2)}

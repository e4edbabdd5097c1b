"""Rate-limited log lines with counts (a publisher gone wild must not flood the log; docs/bad_input.md row 49).

A node reports a rejected message through :meth:`RateLimitedLog.report` under a *key* (topic and reason): the
first one is logged at once, later ones at most once per ``period`` seconds, each line saying how many were
rejected under that key since the previous line and in all. A 1 kHz flood of bad messages thus writes about one
line a second per key instead of a thousand.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable

_NUMBER = re.compile(r"-?\d+(\.\d+)?(e[-+]?\d+)?")


def reason_key(text: str) -> str:
    """``text`` with its numbers masked: rejections that differ only in a step, stamp or value share a key."""
    return _NUMBER.sub("#", text)


class RateLimitedLog:
    """``report(key, text)``: one line now, then at most one line per ``period`` with the counts."""

    MAX_KEYS = 256  # bounded: keys come from topics and reasons, not from message content

    def __init__(self, emit: Callable[[str], None], period: float = 1.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.emit = emit
        self.period = float(period)
        self.clock = clock
        self.total: dict[str, int] = {}
        self._since: dict[str, int] = {}
        self._last: dict[str, float] = {}

    def __call__(self, text: str) -> bool:
        """Report ``text`` under its own :func:`reason_key`."""
        return self.report(reason_key(text), text)

    def report(self, key: str, text: str) -> bool:
        """Count one rejection under ``key``; log ``text`` (with counts) if due. True when a line was written."""
        if key not in self.total and len(self.total) >= self.MAX_KEYS:
            key = "(other)"
        self.total[key] = self.total.get(key, 0) + 1
        self._since[key] = self._since.get(key, 0) + 1
        now = self.clock()
        if now - self._last.get(key, -float("inf")) < self.period:
            return False
        n, total = self._since[key], self.total[key]
        self._since[key], self._last[key] = 0, now
        suffix = "" if total == 1 else f" [{n} like it since the last line, {total} in all; at most one line per " \
                                       f"{self.period:g} s]"
        self._write(text + suffix)
        return True

    def _write(self, line: str) -> None:
        # rclpy refuses a second severity from one call site ("Logger severity cannot be changed between calls"),
        # so each severity of a bound rclpy logger method is called from a line of its own
        name, logger = getattr(self.emit, "__name__", ""), getattr(self.emit, "__self__", None)
        if logger is not None and name == "error":
            logger.error(line)
        elif logger is not None and name in ("warning", "warn"):
            logger.warning(line)
        elif logger is not None and name == "info":
            logger.info(line)
        else:
            self.emit(line)

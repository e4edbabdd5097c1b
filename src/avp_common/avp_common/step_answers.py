"""The step rules a lock-step node applies to its observations (docs/perception.md "step rules", issue #20).

A node keeps its last answer: a re-sent copy of the step it answered gets the same answer again, at most once per
:data:`~avp_common.qos.RESEND_ANSWER_INTERVAL` (a flood of copies must not become a flood of answers); a step
older than the last answered one is dropped unless it is step 0 (a new episode).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from avp_common.qos import RESEND_ANSWER_INTERVAL


class StepAnswers:
    """The last step a node answered and its answer (whatever the node re-publishes for a copy of that step)."""

    def __init__(self) -> None:
        self.last_step = -1
        self.answer: Any = None
        self.answered_at = -float("inf")  # wall time of the last (re-)publication

    def reset(self) -> None:
        """Forget the episode (a new lot map or a new episode)."""
        self.last_step, self.answer = -1, None

    def store(self, step: int, answer: Any) -> None:
        """``answer`` was just published for ``step``."""
        self.last_step, self.answer = step, answer
        self.answered_at = time.monotonic()

    def is_copy(self, step: int, republish: Callable[[Any], None]) -> bool:
        """True when ``step`` is the step answered last (a re-sent observation or a copy of it); then
        ``republish(answer)`` is called unless it was within the last ``RESEND_ANSWER_INTERVAL`` seconds."""
        if step != self.last_step or self.answer is None:
            return False
        if time.monotonic() - self.answered_at >= RESEND_ANSWER_INTERVAL:
            republish(self.answer)
            self.answered_at = time.monotonic()
        return True

    def stale(self, step: int) -> str | None:
        """Why ``step`` is dropped (older than the last answered step, and not a new episode's step 0), or None."""
        if 0 < step < self.last_step:
            return f"step {step} is older than step {self.last_step} (out of order or a stale copy); dropped"
        return None

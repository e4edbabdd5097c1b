"""The step rules a lock-step node applies to its observations (docs/perception.md "step rules"; docs/bad_input.md).

Every observation carries the simulator's episode id (:func:`avp_common.msg_auth.episode_of`, covered by the
tag). A node keeps the episode and the last step it answered, and that answer:

* an observation of a **later** episode starts a new episode (the node resets its state);
* one of an **earlier** episode is dropped — a replayed recording, never a reset;
* in the running episode, a copy of the step answered last (a re-sent observation, or a foreign process's replay
  of it, step 0 included) gets the same answer again, at most once per
  :data:`~avp_common.qos.RESEND_ANSWER_INTERVAL` (a flood of copies must not become a flood of answers); a step
  older than the last answered one is dropped.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from avp_common.qos import RESEND_ANSWER_INTERVAL


class StepAnswers:
    """The episode and last step a node answered and its answer (what the node re-publishes for a copy)."""

    def __init__(self) -> None:
        self.episode = -1  # none yet
        self.last_step = -1
        self.answer: Any = None
        self.answered_at = -float("inf")  # wall time of the last (re-)publication

    def reset(self) -> None:
        """Forget the answers (a new lot map, or a new episode); the episode id is kept, so that a replay of an
        earlier episode is still told apart."""
        self.last_step, self.answer = -1, None

    def begin(self, episode: int) -> bool:
        """Enter ``episode`` if it is a later one (answers forgotten); True when it was new and an episode ran
        before (the caller resets its own state)."""
        if episode <= self.episode:
            return False
        had = self.episode >= 0
        self.episode = episode
        self.reset()
        return had

    def store(self, step: int, answer: Any) -> None:
        """``answer`` was just published for ``step``."""
        self.last_step, self.answer = step, answer
        self.answered_at = time.monotonic()

    def is_copy(self, step: int, republish: Callable[[Any], None], episode: int) -> bool:
        """True when ``step`` of ``episode`` is the step of the running episode answered last (a re-sent
        observation or a copy of it); then ``republish(answer)`` is called unless it was within the last
        ``RESEND_ANSWER_INTERVAL`` seconds."""
        if episode != self.episode or step != self.last_step or self.answer is None:
            return False
        if time.monotonic() - self.answered_at >= RESEND_ANSWER_INTERVAL:
            republish(self.answer)
            self.answered_at = time.monotonic()
        return True

    def stale(self, step: int, episode: int) -> str | None:
        """Why ``step`` of ``episode`` is dropped (an earlier episode; or older than the last answered step of the
        running one), or None."""
        if episode < self.episode:
            return f"step {step} of an episode that ended (a replay of an earlier episode); dropped"
        if episode == self.episode and step < self.last_step:
            return f"step {step} is older than step {self.last_step} (out of order or a stale copy); dropped"
        return None

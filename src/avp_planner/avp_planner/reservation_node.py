"""reservation node: the spot-reservation book of several egos in the live graph (docs/world.md, "Several egos").

The centralised reference of the method profile ``reserve``, as the oracle is for one ego: a message between the egos,
not something an ego observes. It sits between the simulator and each ``reserve`` ego's pipeline
(avp_bringup.graph.fleet_graph remaps that pipeline's ``observation`` to ``reserved/observation``):

  subscribes  ego<i>/observation (tagged by the simulator with ego i's key), ego<i>/decision (ego i's planner),
              ego<i>/episode_status, for each ego i of parameter ``egos``
  publishes   ego<i>/reserved/observation: the observation with the spots other egos hold moved from vacant to
              occupied (:meth:`avp_planner.core.reservation.SpotReservations.hide`), tagged with ego i's key

Each ego plans step k with the holds as they stood after step k-1 (:meth:`SpotReservations.settle`): in lock-step the
node forwards observation k once it has every step k-1 decision of the egos it forwarded step k-1 to, and their
statuses of step k (a hold ends when its ego parks, crashes or times out); the same seed then gives the in-process
fleet's episode. In real time it forwards at once, with the book as it stands. A hold also ends when its ego has
not decided for ``timeout`` s of simulated time.
"""

from __future__ import annotations

import sys
import time

from rclpy.node import Node

from avp_common.conversions import time_to_ns
from avp_common.msg_auth import Authenticator, episode_of
from avp_common.node_main import run_node
from avp_common.params import ParamSpec, declare_and_validate
from avp_common.qos import STATUS, STEP
from avp_common.ratelog import RateLimitedLog
from avp_msgs.msg import EpisodeStatus, Observation, PlannerDecision
from avp_planner.core.reservation import SpotReservations

RESERVATION_PARAMS = [
    ParamSpec("egos", str, "Indices of the egos that plan with the book (those running the profile reserve), "
              "comma-separated.", default="0,1"),
    ParamSpec("min_subscribers", int, "Forward an ego's first observation once its reserved/observation has this "
              "many subscribers (its pipeline's belief, prediction and planner nodes).", min=0, default=3),
    ParamSpec("timeout", float, "A hold ends when its ego has not decided for this long [s, simulated time].",
              min=0.1, default=5.0),
    ParamSpec("lockstep", bool, "Wait for the step before's decisions before forwarding an observation (the "
              "simulator's mode lockstep); false: forward at once.", default=True),
]
_RUNNING = (EpisodeStatus.STATE_IDLE, EpisodeStatus.STATE_RUNNING)


class _Decided:
    """What the book needs of a decision (the fields :meth:`SpotReservations.update` reads)."""

    def __init__(self, msg: PlannerDecision):
        self.mode = {PlannerDecision.MODE_PARK: "park", PlannerDecision.MODE_EXPLORE: "explore"}.get(msg.mode, "idle")
        self.spot_id = int(msg.spot_id)


class ReservationNode(Node):
    def __init__(self) -> None:
        super().__init__("avp_reservation")
        p = declare_and_validate(self, RESERVATION_PARAMS)
        try:
            self.egos = sorted({int(i) for i in str(p["egos"]).split(",")})
        except ValueError:
            self.egos = []
        if not self.egos or any(not 0 <= i < 8 for i in self.egos):
            raise ValueError(f"parameter 'egos': {p['egos']!r}: comma-separated indices of egos 0..7")
        self.min_subscribers = int(p["min_subscribers"])
        self.timeout, self.lockstep = float(p["timeout"]), bool(p["lockstep"])
        self.auth = Authenticator(self)
        self.waiting = RateLimitedLog(self.get_logger().warning, period=5.0)  # what a held observation waits for
        self.pub = {i: self.auth.publisher(Observation, f"ego{i}/reserved/observation", STEP, ego=i) for i in self.egos}
        for i in self.egos:
            self.auth.subscription(Observation, f"ego{i}/observation", lambda m, i=i: self._on_obs(i, m), STEP)
            self.auth.subscription(PlannerDecision, f"ego{i}/decision", lambda m, i=i: self._on_decision(i, m), STEP)
            self.create_subscription(EpisodeStatus, f"ego{i}/episode_status", lambda m, i=i: self._on_status(i, m),
                                     STATUS)
        self._new_episode(-1)
        self.create_timer(0.05, self._forward)  # an observation held for its pipeline's subscribers goes out later

    def _new_episode(self, episode: int) -> None:
        self.episode = episode
        self.book = SpotReservations(self.timeout)
        self.pending: dict[int, Observation] = {}  # ego -> observation not forwarded yet
        self.sent: dict[int, tuple[int, Observation]] = {}  # ego -> (step, what it was sent): a re-send repeats it
        self.decided: dict[int, dict[int, _Decided]] = {}  # step -> {ego: its decision}
        self.status: dict[int, tuple[int, int]] = {}  # ego -> (step, state) of its newest status
        self.settled = -1  # the last step whose decisions the book holds
        self.blocked_since: float | None = None  # wall time an observation began to wait (lock-step)

    def _on_obs(self, i: int, msg: Observation) -> None:
        episode = episode_of(msg.header.frame_id)
        if episode != self.episode:
            if episode < self.episode:
                return  # a replay of an older episode
            self._new_episode(episode)
        step = int(msg.step)
        if i in self.sent and self.sent[i][0] == step:  # the simulator re-sent it (lock-step): the same answer
            self.pub[i].publish(self.sent[i][1])
            return
        self.pending[i] = msg
        self._forward()

    def _on_decision(self, i: int, msg: PlannerDecision) -> None:
        if episode_of(msg.header.frame_id) == self.episode and int(msg.step) > self.settled:
            self.decided.setdefault(int(msg.step), {})[i] = _Decided(msg)
            self._forward()

    def _on_status(self, i: int, msg: EpisodeStatus) -> None:
        self.status[i] = (int(msg.step), int(msg.state))
        self._forward()

    def _ready(self, step: int) -> bool:
        """Lock-step: every ego sent step - 1 has decided it, and its status of ``step`` has come."""
        if not self.lockstep or step - 1 <= self.settled:  # settled: the book already holds step - 1
            return True
        prev = [i for i, (s, _) in self.sent.items() if s == step - 1]
        missing = [f"ego {i}'s {'decision' if i not in self.decided.get(step - 1, {}) else 'status'}" for i in prev
                   if i not in self.decided.get(step - 1, {}) or self.status.get(i, (-1, 0))[0] < step]
        now = time.monotonic()
        if not missing:
            self.blocked_since = None
        elif self.blocked_since is None:
            self.blocked_since = now
        elif now - self.blocked_since > 2.0:  # one step's wait is normal; this long is not
            self.waiting.report("wait", f"observation {step} held for {now - self.blocked_since:.0f} s: waiting for "
                                        f"{', '.join(missing)} of step {step - 1}")
        return not missing

    def _forward(self) -> None:
        for step in sorted({int(m.step) for m in self.pending.values()}):
            if not self._ready(step):
                return
            if step - 1 > self.settled:  # the holds after step - 1: its decisions in ego order, then the ends
                now = (step - 1) * self._dt()
                self.book.settle(self.decided.pop(step - 1, {}), now)
                for i, (_, state) in self.status.items():
                    if state not in _RUNNING:
                        self.book.release(i)
                self.book.expire(now)
                self.settled = step - 1
            for i in [i for i, m in self.pending.items() if int(m.step) == step]:
                if i not in self.sent and self.pub[i].get_subscription_count() < self.min_subscribers:
                    continue  # its pipeline is not up yet (its first observation would be lost)
                msg = self.pending.pop(i)
                moved = self.book.hide(msg.vacant_spot_ids, msg.occupied_spot_ids, i)
                if moved is not None:
                    msg.vacant_spot_ids = [int(x) for x in moved[0]]
                    msg.occupied_spot_ids = [int(x) for x in moved[1]]
                self.sent[i] = (step, msg)
                self.pub[i].publish(msg)

    def _dt(self) -> float:
        m = next(iter(self.pending.values()))
        return float(m.dt) if m.dt > 0 else time_to_ns(m.header.stamp) * 1e-9 / max(int(m.step), 1)


def main(args=None) -> int:
    return run_node(ReservationNode, "avp_reservation", args)


if __name__ == "__main__":
    sys.exit(main())

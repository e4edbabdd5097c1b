"""The relay between the simulator and the egos of a fleet that both fleet nodes share (docs/world.md, "Several
egos"): the spot-reservation book (:mod:`avp_planner.reservation_node`) and the V2V channel
(:mod:`avp_planner.v2v_node`).

A relay subscribes, for each ego i of parameter ``egos``, to its input observation (``ego<i>/observation`` or what
:meth:`LockstepRelay.source` names), its planner's ``ego<i>/decision`` and its ``ego<i>/episode_status``, and
publishes ``ego<i>/<output>``: what :meth:`LockstepRelay.transform` makes of the observation (the observation
changed, or another message of that step), tagged with ego i's key.
Each ego plans step k with what the relay made of step k-1 (:meth:`LockstepRelay.settle`): in lock-step it forwards
observation k once it has every step k-1 decision of the egos it forwarded step k-1 to (and, where
:attr:`LockstepRelay.needs_status`, their statuses of step k); the same seed then gives the in-process fleet's
episode. In real time it forwards at once: when ``lockstep`` is false, and whenever the simulator's episode status
says it steps in real time (``lock_step`` false), whatever the parameter says — a real-time planner skips the steps
it falls behind on, so a decision waited for may never come, and one ego's slow step must not hold another's. A
re-sent observation (lock-step) gets the same answer again; an ego's first observation waits until
``min_subscribers`` read its output (its pipeline is up).
"""

from __future__ import annotations

import time

from rclpy.node import Node

from avp_common.conversions import time_to_ns
from avp_common.msg_auth import Authenticator, episode_of
from avp_common.params import ParamSpec, declare_and_validate
from avp_common.qos import QUIET_READER, STATUS, STEP
from avp_common.ratelog import RateLimitedLog
from avp_msgs.msg import EpisodeStatus, Observation, PlannerDecision

#: the parameters every relay has (its list names them, with its own)
RELAY_PARAMS = [
    ParamSpec("egos", str, "Indices of the egos whose observations pass through this node, comma-separated.",
              default="0,1"),
    ParamSpec("min_subscribers", int, "Forward an ego's first observation once its output topic has this many "
              "subscribers (its pipeline's belief, prediction and planner nodes).", min=0, default=3),
    ParamSpec("lockstep", bool, "Wait for the step before's decisions before forwarding an observation while the "
              "simulator steps in lock-step (its episode status says so); false: forward at once.", default=True),
]


def parse_egos(text: str, name: str = "egos") -> list[int]:
    """Comma-separated ego indices 0..7 (sorted, unique); ValueError naming parameter ``name``."""
    try:
        egos = sorted({int(i) for i in str(text).split(",") if i.strip()})
    except ValueError:
        egos = [-1]
    if any(not 0 <= i < 8 for i in egos):
        raise ValueError(f"parameter '{name}': {text!r}: comma-separated indices of egos 0..7")
    return egos


class LockstepRelay(Node):
    """See the module docstring. Subclasses set :attr:`output`, and override :meth:`reset`, :meth:`settle`,
    :meth:`transform` and :meth:`source` as they need."""

    output = "relayed/observation"
    output_type = Observation  # what transform() returns
    needs_status = False  # lock-step also waits for each ego's status of the step (a hold ends with its episode)
    #: what makes the relay's input of an observation's checked bytes; None: the whole Observation (a relay that
    #: reads only the step and the ego's pose takes :func:`avp_common.received.observation_head`)
    read_input = None

    def __init__(self, name: str, params: list[ParamSpec]) -> None:
        """``params``: the node's parameters, :data:`RELAY_PARAMS`' names among them."""
        super().__init__(name)
        self.params = p = declare_and_validate(self, params)
        self.egos = parse_egos(p["egos"])
        if not self.egos:
            raise ValueError(f"parameter 'egos': {p['egos']!r}: comma-separated indices of egos 0..7")
        self.min_subscribers, self.lockstep = int(p["min_subscribers"]), bool(p["lockstep"])
        self.sim_lockstep = True  # what the simulator's newest episode status says (lock_step)
        self.auth = Authenticator(self)
        self.waiting = RateLimitedLog(self.get_logger().warning, period=5.0)  # what a held observation waits for
        self.pub = {i: self.auth.publisher(self.output_type, f"ego{i}/{self.output}", STEP, ego=i)
                    for i in self.egos}
        for i in self.egos:
            self.auth.subscription(Observation, self.source(i), lambda m, i=i: self._on_obs(i, m), STEP,
                                   read=self.read_input)
            self.auth.subscription(PlannerDecision, f"ego{i}/decision", lambda m, i=i: self._on_decision(i, m), STEP)
            self.create_subscription(EpisodeStatus, f"ego{i}/episode_status", lambda m, i=i: self._on_status(i, m),
                                     STATUS, event_callbacks=QUIET_READER)
        self._new_episode(-1)
        self.create_timer(0.05, self._forward)  # an observation held for its pipeline's subscribers goes out later

    # ----------------------------------------------------------------------------------------------- the hooks

    def source(self, i: int) -> str:
        """The topic ego i's observation comes in on."""
        return f"ego{i}/observation"

    def reset(self) -> None:
        """A new episode begins: forget what the last one left."""

    def settle(self, step: int, decided: dict[int, PlannerDecision], now: float) -> None:
        """Take in the decisions of ``step`` (ego -> its decision, in ego order; in real time: those that came) at
        simulated time ``now``, before the observations of ``step + 1`` go out."""

    def transform(self, i: int, msg: Observation):
        """What goes out to ego i for its observation ``msg`` (an :attr:`output_type`: the observation changed in
        place, or a new message)."""
        return msg

    # ------------------------------------------------------------------------------------------- the relaying

    def _new_episode(self, episode: int) -> None:
        self.episode = episode
        self.pending: dict[int, Observation] = {}  # ego -> observation (or what read_input made of it) not forwarded
        self.sent: dict[int, tuple[int, object]] = {}  # ego -> (step, what it was sent): a re-send repeats it
        self.decided: dict[int, dict[int, PlannerDecision]] = {}  # step -> {ego: its decision}
        self.status: dict[int, tuple[int, int]] = {}  # ego -> (step, state) of its newest status
        self.settled = -1  # the last step whose decisions are taken in
        self.blocked_since: float | None = None  # wall time an observation began to wait (lock-step)
        self.reset()

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
            self.decided.setdefault(int(msg.step), {})[i] = msg
            self._forward()

    def _on_status(self, i: int, msg: EpisodeStatus) -> None:
        self.status[i] = (int(msg.step), int(msg.state))
        self.sim_lockstep = bool(msg.lock_step)
        self._forward()

    def _ready(self, step: int) -> bool:
        """Lock-step: every ego sent step - 1 has decided it (and its status of ``step`` has come)."""
        if not (self.lockstep and self.sim_lockstep) or step - 1 <= self.settled:  # settled: step - 1 taken in
            return True
        prev = [i for i, (s, _) in self.sent.items() if s == step - 1]
        missing = [f"ego {i}'s {'decision' if i not in self.decided.get(step - 1, {}) else 'status'}" for i in prev
                   if i not in self.decided.get(step - 1, {})
                   or (self.needs_status and self.status.get(i, (-1, 0))[0] < step)]
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
            if step - 1 > self.settled:  # the decisions of step - 1, in ego order
                decided = self.decided.pop(step - 1, {})
                self.settle(step - 1, dict(sorted(decided.items())), (step - 1) * self._dt())
                self.settled = step - 1
            for i in [i for i, m in self.pending.items() if int(m.step) == step]:
                if i not in self.sent and self.pub[i].get_subscription_count() < self.min_subscribers:
                    continue  # its pipeline is not up yet (its first observation would be lost)
                msg = self.transform(i, self.pending.pop(i))
                self.sent[i] = (step, msg)
                self.pub[i].publish(msg)

    def _dt(self) -> float:
        m = next(iter(self.pending.values()))
        return float(m.dt) if m.dt > 0 else time_to_ns(m.header.stamp) * 1e-9 / max(int(m.step), 1)

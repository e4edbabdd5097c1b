"""Why the ego is not moving (docs/stuck_ego.md): the decision trace of every step, and its per-episode summary.

Every :class:`~avp_motion.planner_types.Decision` carries ``trace``: the step's **mode** —

* ``park`` / ``explore``: driving a parking / exploration plan (§V-D-1, §V-D-2);
* ``wait_and_go``: standing at the start of a plan that was found feasible only after a wait (Nawaz et al.'s
  wait-and-go, our ``max_wait``);
* ``detour``: driving a plan found with the standing agents as static obstacles (``dynamic_as_static_fallback``);
* ``evasive``: driving away because standing still is predicted to be hit (``evasive``);
* ``creep``: inching along the best blocked plan after standing ``stuck_time`` (``deadlock_breaker``, mechanism d);
* ``make_way``: stepping out of the way of a standing car that waits for the ego (``make_way``, mechanism e);
* ``idle``: u = 0 (§V-D-3); ``parked``: at the end of the parking plan —

and, for every idle or waiting step, the **cause**:

* ``agent``: every statically feasible plan met a predicted agent; the blocker is named — its id, whether it is
  a pedestrian, the probability of the hypothesis hit, the time index k of the first conflict (on the blocked plan
  hit latest) and how the agent moves now (:func:`agent_motion`: ``standing``, ``braking``, ``towards`` or
  ``away`` from the ego); the cause key is ``vehicle:<motion>`` or ``pedestrian:<motion>``;
* ``static``: no statically feasible path to any candidate spot or exploration point;
* ``no_candidate``: no candidate spot and no exploration point to search;
* ``budget``: the searches ran out of time (``decision_time_cap`` / the real-time deadline);
* ``making_way``: standing aside after ``make_way`` until the car it made way for has moved (its id named);
* ``invalid_input``: the inputs were refused.

:class:`DecisionTrace` folds the steps of an episode into counts: steps per mode, idle steps per cause, the longest
idle spell and the longest spells with their causes (the answer to "why is my car stuck?", ``avp why``).
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from avp_motion.control import reference_trajectory
from avp_world.types import Observation

MODES = ("park", "explore", "wait_and_go", "detour", "evasive", "creep", "make_way", "idle", "parked")
STANDING_SPEED = 0.3  # m/s, as planner_types.STILL_SPEED
BRAKING_DROP = 0.3  # m/s lost over the last BRAKING_WINDOW s: braking
BRAKING_WINDOW = 0.5  # s


def agent_motion(obs: Observation, agent_id: int, pedestrian: bool) -> str:
    """How an observed agent moves now: ``standing`` (slower than 0.3 m/s), ``braking`` (0.3 m/s slower than
    0.5 s ago), else ``towards`` / ``away`` (its velocity's component along the direction to the ego);
    ``unseen`` if it is not observed."""
    ego = np.asarray(obs.ego_pose[:2], dtype=float)
    if pedestrian:
        p = next((q for q in obs.pedestrians if int(q.id) == agent_id), None)
        if p is None:
            return "unseen"
        pos, vel = np.asarray(p.position, float), (np.asarray(p.position) - np.asarray(p.previous_position)) / obs.dt
        before = float(np.hypot(*vel))
    else:
        v = next((q for q in obs.vehicles if int(q.id) == agent_id), None)
        if v is None:
            return "unseen"
        h = np.asarray(v.history, dtype=float).reshape(-1, 3)
        if len(h) < 2:
            return "standing"
        pos, vel = h[-1, :2], (h[-1, :2] - h[-2, :2]) / obs.dt
        n = int(round(BRAKING_WINDOW / obs.dt))
        before = float(np.hypot(*(h[-1 - n, :2] - h[-2 - n, :2]))) / obs.dt if len(h) >= n + 2 else 0.0
    speed = float(np.hypot(*vel))
    if speed < STANDING_SPEED:
        return "standing"
    if before - speed > BRAKING_DROP:
        return "braking"
    return "towards" if float(np.dot(vel, ego - pos)) > 0.0 else "away"


def blocker_trace(dyn, poses: np.ndarray, obs: Observation) -> dict:
    """The cause entry naming the first predicted agent that meets ``poses`` (time-indexed from now)."""
    b = dyn.blocker(poses)
    if b is None:
        return {"cause": "agent"}
    k, ped, agent, prob = b
    return {"cause": "agent", "agent_id": agent, "pedestrian": ped, "probability": round(float(prob), 4),
            "hit_step": k, "motion": agent_motion(obs, agent, ped)}


def blocked_poses(st, control) -> np.ndarray | None:
    """The poses (time-indexed from now) of the blocked plan of a decision step met latest by a predicted agent
    (ties: the shorter), or None if no plan was blocked: the plan the ego waits to drive."""
    if not st.blocked_plans:
        return None
    c = max(st.blocked_plans, key=lambda c: (c.first_hit if c.first_hit >= 0 else 10**9, -c.path.length))
    poses, _ = reference_trajectory(c.path, control, float(st.obs.ego_speed))
    return poses


def idle_cause(st, control, poses: np.ndarray | None = None) -> dict:
    """Why a decision step (:class:`~avp_motion.planner_types._Step`) ends idle: the blocked plan hit latest
    (``poses``, :func:`blocked_poses`) names its blocker (``agent``); else ``budget`` (a search hit the time cap, or
    the deadline passed), ``static`` (searches ran, none found a path) or ``no_candidate`` (nothing to search)."""
    if poses is None:
        poses = blocked_poses(st, control)
    if poses is not None:
        return blocker_trace(st.dyn, poses, st.obs)
    queries = st.stats.get("queries", [])
    if any(str(q.get("reason", "")).startswith("time cap") for q in queries) or time.perf_counter() > st.t_end:
        return {"cause": "budget"}
    return {"cause": "static" if queries else "no_candidate"}


def step_of(decision) -> tuple[str, dict, bool]:
    """(mode, trace, whether the ego stands idle or waiting) of one decision: what is counted and published."""
    tr = getattr(decision, "trace", None) or {}
    mode = tr.get("mode", decision.mode)
    return mode, tr, abs(float(decision.command[0])) < 1e-9 and mode in ("idle", "wait_and_go")


def cause_key(trace: dict) -> str:
    """The cause of an idle/waiting step as one key (``vehicle:standing``, ``static``, ...)."""
    cause = trace.get("cause", "unknown")
    if cause == "agent":
        return f"{'pedestrian' if trace.get('pedestrian') else 'vehicle'}:{trace.get('motion', 'unseen')}"
    return cause


@dataclass
class _Spell:
    start: int
    end: int
    causes: Counter = field(default_factory=Counter)
    agents: Counter = field(default_factory=Counter)

    def as_dict(self, dt: float) -> dict:
        cause, n = self.causes.most_common(1)[0]
        out = {"start_step": self.start, "steps": self.end - self.start + 1,
               "start_s": round(self.start * dt, 2), "seconds": round((self.end - self.start + 1) * dt, 2),
               "cause": cause, "cause_share": round(n / sum(self.causes.values()), 3)}
        if self.agents:
            out["blocking_agents"] = [int(a) for a, _ in self.agents.most_common(3)]
        return out


class DecisionTrace:
    """Per-episode counts of the decision trace (see the module docstring). ``add`` every step's decision."""

    def __init__(self, dt: float = 0.1, keep_spells: int = 10):
        self.dt, self.keep = float(dt), int(keep_spells)
        self.modes: Counter = Counter()
        self.causes: Counter = Counter()
        self.spells: list[_Spell] = []
        self._open: _Spell | None = None

    def add(self, step: int, decision) -> int:
        """Count one step's decision; returns the length of the idle spell it is part of (0 if it moves)."""
        mode, tr, still = step_of(decision)
        agent = tr.get("agent_id")
        return self.add_step(step, mode, cause_key(tr) if still else "", None if agent is None else int(agent))

    def add_step(self, step: int, mode: str, cause: str, agent_id: int | None = None) -> int:
        """Count one step given its mode and, when idle or waiting (``cause`` not ""), its cause key."""
        self.modes[mode] += 1
        if not cause:
            self._close()
            return 0
        self.causes[cause] += 1
        if self._open is None or self._open.end != step - 1:
            self._close()
            self._open = _Spell(step, step)
        self._open.end = step
        self._open.causes[cause] += 1
        if agent_id is not None and agent_id >= 0:
            self._open.agents[agent_id] += 1
        return self._open.end - self._open.start + 1

    def _close(self) -> None:
        if self._open is not None:
            self.spells.append(self._open)
            self._open = None

    def summary(self) -> dict:
        """``steps_by_mode``, ``idle_steps_by_cause``, ``longest_idle_steps`` and the ``keep_spells`` longest
        ``idle_spells`` (start, length, main cause and its share, blocking agents), JSON-ready."""
        self._close()
        longest = sorted(self.spells, key=lambda s: (-(s.end - s.start), s.start))[: self.keep]
        return {"steps_by_mode": dict(sorted(self.modes.items())),
                "idle_steps_by_cause": dict(sorted(self.causes.items())),
                "longest_idle_steps": max((s.end - s.start + 1 for s in self.spells), default=0),
                "idle_spells": [s.as_dict(self.dt) for s in sorted(longest, key=lambda s: s.start)]}


def spells_text(summary: dict, dt: float = 0.1) -> str:
    """The idle spells of an episode's trace summary as lines for a user (``avp why``)."""
    lines = [f"steps by mode: {summary.get('steps_by_mode', {})}",
             f"idle steps by cause: {summary.get('idle_steps_by_cause', {})}",
             f"longest idle spell: {summary.get('longest_idle_steps', 0)} steps "
             f"({summary.get('longest_idle_steps', 0) * dt:.1f} s)"]
    for s in summary.get("idle_spells", []):
        who = f"; blocking agent(s) {s['blocking_agents']}" if s.get("blocking_agents") else ""
        lines.append(f"  t = {s['start_s']:6.1f} s for {s['seconds']:5.1f} s: {s['cause']} "
                     f"({100 * s['cause_share']:.0f} % of its steps){who}")
    return "\n".join(lines)


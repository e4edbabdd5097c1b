"""The planner's decision trace as an avp_msgs/DecisionTrace message, and back.

The node publishes one per decision on ``~/debug/decision``; ``avp why`` reads them back from a bag
(:func:`trace_from_msg` feeds :class:`avp_motion.trace.DecisionTrace`).
"""

from __future__ import annotations

from avp_motion.trace import cause_key, step_of
from avp_msgs.msg import DecisionTrace


def trace_to_msg(header, step: int, decision, idle_steps: int) -> DecisionTrace:
    """Step ``step``'s trace (``decision.trace`` of :class:`~avp_motion.planner_types.Decision`)."""
    mode, tr, still = step_of(decision)
    msg = DecisionTrace()
    msg.header = header
    msg.step = int(step)
    msg.mode = str(mode)
    msg.cause = str(tr.get("cause", "")) if still else ""
    msg.cause_key = cause_key(tr) if still else ""
    msg.agent_id = int(tr.get("agent_id", -1)) if still else -1
    msg.agent_is_pedestrian = bool(tr.get("pedestrian", False)) if still else False
    msg.probability = float(tr.get("probability", 0.0)) if still else 0.0
    msg.conflict_step = int(tr.get("hit_step", -1)) if still else -1
    msg.agent_motion = str(tr.get("motion", "")) if still else ""
    msg.idle_steps = int(idle_steps)
    msg.reason = str(getattr(decision, "reason", ""))
    return msg


def trace_from_msg(msg: DecisionTrace) -> tuple[int, str, str, int | None]:
    """(step, mode, cause key or "" while driving, blocking agent id or None) for ``DecisionTrace.add_step``."""
    return int(msg.step), str(msg.mode), str(msg.cause_key), (int(msg.agent_id) if msg.agent_id >= 0 else None)

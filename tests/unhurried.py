"""Planner settings without wall-clock caps, for tests that judge decisions and paths, not the machine's speed."""

from dataclasses import replace

from avp_episode.profiles import DETERMINISTIC_PLANNER
from avp_motion.settings import PlannerSettings


def unhurried(s: PlannerSettings | None = None) -> PlannerSettings:
    """``s`` (default: the shipped settings) with the caps ``avp experiment`` lifts (DETERMINISTIC_PLANNER)."""
    s = s or PlannerSettings()
    return replace(s, search=replace(s.search, time_cap=DETERMINISTIC_PLANNER["search.time_cap"]),
                   decision=replace(s.decision, decision_time_cap=DETERMINISTIC_PLANNER["decision.decision_time_cap"],
                                    fallback_time_cap=DETERMINISTIC_PLANNER["decision.fallback_time_cap"]))

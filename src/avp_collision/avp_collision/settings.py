"""Settings of collision checking (ROS-free, a frozen dataclass): the ego's footprint against the static world and
the predicted agents (paper §V-D). :class:`~avp_search.settings.SearchConfig` carries one as ``collision``. Units:
metres, seconds.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class CollisionSettings:
    """Static world (occupancy grid + EDT) and footprint checks (§V-D: V_0,τ ⊆ L, V_0,τ ∩ S_i = ∅ for b ≥ β)."""

    grid_resolution: float = 0.1  # occupancy grid / Euclidean distance transform cell size
    n_discs: int = 4  # covering discs of the footprint used by the conservative EDT pre-check
    footprint_margin: float = 0.15  # clearance every searched sample keeps to static obstacles
    verify_margin: float = 0.05  # clearance the executed eq. (1) states keep to static obstacles
    start_relax_distance: float = 0.6  # arc length near the ego's current pose checked with verify_margin only
    # extra (§V-D asks V ⊆ L of an ego that knows its pose): with a localisation covariance (noisy sensing) the ego
    # plans inside L shrunk by this many of its standard deviations, spots kept whole (avp_collision.localisation);
    # exact sensing reports no covariance, so the paper's setting is unchanged
    localisation_sigmas: float = 2.0  # extra: L shrunk by this many localisation std devs under noisy sensing; 0 = L
    # extra: L' also keeps the ego's own estimated footprint whole where L' leaves it outside (at a wall the
    # estimate has drifted towards, e.g. the entrance it starts at), so that the margin alone never holds it still;
    # false: the ego plans only inside L' and stands while its estimate is nearer a wall than the margin
    localisation_keep_start: bool = False  # extra: the ego's own footprint kept inside L' (false: L' alone)
    vehicle_margin: float = 0.3  # clearance to predicted vehicle footprints (§V-D, time-indexed)
    pedestrian_margin: float = 0.4  # clearance to predicted pedestrian discs
    keep_current_gap: bool = True  # extra: an agent already nearer than the margin need only keep its gap (§V-D: no)
    beyond_horizon: str = "hold"  # a prediction after its last pose: "hold" it there | "release" (no obstacle)
    # mechanism b (beyond §V-D, which checks every predicted trajectory as an obstacle): > 0 = a plan meeting
    # a hypothesis only after this many seconds is blocked only when the hypotheses it meets there sum to more than
    # risk_bound in probability; 0 = every meeting blocks (the paper)
    commit_horizon: float = 0.0  # mechanism b: s of hard checks against every hypothesis, then beyond_commit (0: off)
    risk_bound: float = 0.5  # mechanism b, risk: hypotheses met past the window may sum to this probability
    # beyond the commit window: "risk" (the risk bound above) | "hold" (each hypothesis is an obstacle where it is at
    # the window's end, as §III-B's reactive agents stop for the ego; commit_horizon -> 0 is the `blind` bound)
    beyond_commit: str = "risk"  # mechanism b: "risk" (risk_bound) or "hold" (each hypothesis held at the window's end)
    # mechanism a in its interactive form (beyond §V-D, which checks each predicted trajectory as if the
    # agent went on whatever the ego does): > 0 = each hypothesis is rolled out against the ego's plan with §III-B's
    # rule, the agent braking while its next reactive_steps steps come within the margin + reactive_margin of the ego
    # (avp_collision.reactive); 0 = the paper
    reactive_steps: int = 2  # agents stop for the ego, look-ahead L [steps] (avp_collision.reactive); 0 = the paper
    reactive_margin: float = 0.0  # m beyond the margin at which an agent is assumed to brake for the ego
    # which agents reactive_steps applies to: "assumed" (every agent), "agent" (only agents seen to stop hard,
    # harder than reactive_decel, with the ego ahead of them within decision.yield_lookahead; remembered for the
    # episode), "lot" (every agent, once any has been seen to do so), "told" (the agents the caller names with
    # EgoPlanner.tell_reacting: the oracle bound's ground truth, avp_episode.oracle)
    # shipped: "assumed"; before 0c50a9b "lot", now the planner profile `wary` (drivers may not stop)
    reactive_evidence: str = "assumed"  # whose reaction: assumed (all), agent (seen), lot (once seen), told (caller)
    # when an agent is assumed to brake for the ego: "margin" (its next reactive_steps poses come within the check's
    # margin + reactive_margin of the ego; the rule since 9c585c4) or "overlap" (they would overlap it +
    # reactive_margin: §III-B's "meets", the simulator's rule; an agent braking for the ego then meets it only if the
    # ego comes nearer)
    reactive_trigger: str = "margin"  # when a reacting agent is assumed to brake: margin or overlap (§III-B)
    reactive_decel: float = 3.0  # m/s^2 of braking (2x ParkSim's 1.5) that counts as stopping for the ego
    # how an agent the reaction applies to is predicted: "rollout" (each hypothesis rolled out against the ego's plan
    # with the braking rule above) or "hold" (held where it is now, as `blind` holds every agent: it will stop for the
    # ego, and the ego re-plans every step; an arm of docs/research/unfreezing.md)
    reactive_model: str = "rollout"  # a reacting agent rolled out with the braking rule, or held where it is
    # which predicted trajectories of an agent are obstacles: "all" (every hypothesis >= mu, §V-D-1 "the predicted
    # trajectories") or "most_likely" (only each agent's most probable one; an arm of docs/research/unfreezing.md)
    hypotheses: str = "all"  # all (§V-D-1) or most_likely (each agent's most probable hypothesis only)
    # the predicted trajectories of a car driving away from the ego (its velocity pointing away from the ego, faster
    # than 0.3 m/s): "hypotheses" (as given, §V-C) or "straight" (replaced by one: straight on at its last displacement,
    # the constant-velocity prediction of §VI-B-1; an arm of docs/research/unfreezing.md)
    receding: str = "hypotheses"  # a car driving away keeps its hypotheses (§V-C) or goes straight on

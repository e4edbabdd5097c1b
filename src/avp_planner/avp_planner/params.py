"""The planner node's parameters (ROS-free): the node's own switches and every field of
:class:`avp_motion.settings.PlannerSettings` as a validated, read-only parameter (config/planner.param.yaml).

Kept apart from the node so that the experiment runner, ``avp params`` and the lifecycle client read them without
rclpy (the in-process runner runs where no ROS is installed).
"""

from __future__ import annotations

from avp_common.params import ParamSpec, specs_from_dataclass
from avp_motion.settings import DEFAULT_SETTINGS

NODE_PARAMS = [
    ParamSpec("autostart", bool, "Lifecycle: configure and activate at start-up; false = stay unconfigured until "
              "`avp swap-planner` (or a lifecycle change_state call) brings the node up.", default=True),
    ParamSpec("use_beliefs", bool, "Wait for and use beliefs (from the belief node); false = beliefs from "
              "observation only.", "b_t", "§V-B", default=False),
    ParamSpec("use_predictions", bool, "Wait for and use predicted trajectories (the prediction node's); false = "
              "none.", "", "§V-C", default=False),
    ParamSpec("auth_inputs", bool, "Take lot_map, observation, beliefs, predictions and ego_intention only when "
              "tagged with the user's key (avp_common.msg_auth); others are dropped and their publishers named.",
              default=True),
    ParamSpec("stale_input_timeout", float, "Real time only (the simulator's episode_status says lock_step false): "
              "an observation whose beliefs / predictions / ego_intention have not come within this many wall "
              "seconds is answered with v = ω = 0 and one log line (a hung perception node); 0 = off. "
              "Lock-step always waits: a late input never changes the episode.", "", "", min=0.0, max=60.0,
              default=0.5),
    ParamSpec("realtime_decision_deadline", float, "Real time only: a decision's searches stop this many wall "
              "seconds after its observation was sent (DDS source timestamp; at least MIN_REALTIME_BUDGET = 10 ms "
              "of searching), so that the command can come before observation k+1 — the simulator ignores a later "
              "one (command_max_lag 0). Beyond the paper, whose planner took 1.28 s a decision (Table I), not real "
              "time. decision.decision_time_cap still holds; 0 = off. Lock-step: unused.", "", "§VI-B",
              min=0.0, max=10.0, default=0.08),
    ParamSpec("use_ego_intention", bool, "Wait for ego_intention (the belief node's ego_intent) and try the "
              "candidate spots in decreasing eta_0,i until one has a safe plan (Table I 'Implicit'); false = the "
              "lowest c_park.", "eta_0,i", "§VI-B-3", default=False),
    ParamSpec("use_beacons", bool, "Wait for v2v/beacons (what the egos before this one announced, avp_v2v; a message "
              "between egos, not in the paper) and plan with them (decision.ego_yield). The fleet graph sets it for "
              "every ego of several; false = none heard.", default=False),
]
PLANNER_PARAMS = NODE_PARAMS + specs_from_dataclass(DEFAULT_SETTINGS)

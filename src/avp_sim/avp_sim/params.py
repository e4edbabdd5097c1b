"""Parameters of the simulator node (config/sim.param.yaml); each row names the paper's symbol."""

from __future__ import annotations

import math

import avp_sensing.noisy as _sensing
from avp_common.params import ParamSpec

SIM_PARAMS: list[ParamSpec] = [
    ParamSpec("lot_file", str, "Lot map YAML; empty = the bundled paper lot (avp_world/maps/paper_lot.yaml).",
              "L", "§II-A", default=""),
    ParamSpec("mode", str, "lockstep: publish step k, wait for the command stamped k, then step; "
              "realtime: step at 1/dt wall rate with the latest command.", choices=("lockstep", "realtime"),
              default="lockstep"),
    ParamSpec("dt", float, "Timestep.", "Δt", "§II-B", min=0.01, max=1.0, default=0.1),
    ParamSpec("t_final", float, "Episode time limit.", "t_f", "§VI-A", min=0.1, default=100.0),
    ParamSpec("t_hist", float, "History length given for every observed vehicle.", "t_hist", "§III-A",
              min=0.0, max=20.0, default=4.0),
    ParamSpec("sensor.n_ray", int, "Number of rays.", "n_ray", "§III-A", min=1, max=100000, default=360),
    ParamSpec("sensor.shape", str, "Shape of the base sensing region Q_0 (ego frame).", "Q_0", "§III-A",
              choices=("disc", "rectangle", "ellipse"), default="disc"),
    ParamSpec("sensor.radius", float, "Disc radius of Q_0.", "Q_0", "§VI-A", min=0.1, default=11.5),
    ParamSpec("sensor.length", float, "Rectangle Q_0: extent along the ego heading.", "Q_0", "§III-A",
              min=0.1, default=23.0),
    ParamSpec("sensor.width", float, "Rectangle Q_0: extent across the ego heading.", "Q_0", "§III-A",
              min=0.1, default=23.0),
    ParamSpec("sensor.semi_major", float, "Ellipse Q_0: semi-axis along the heading.", "Q_0", "§III-A",
              min=0.1, default=11.5),
    ParamSpec("sensor.semi_minor", float, "Ellipse Q_0: semi-axis across the heading.", "Q_0", "§III-A",
              min=0.1, default=11.5),
    ParamSpec("sensor.offset", list, "Centre of Q_0 in the ego frame [x, y].", "Q_0", "§III-A",
              default=[0.0, 0.0]),
    ParamSpec("seed", int, "Scenario seed of the first episode.", "", "§VI-A", min=0, max=2**32 - 1, default=0),
    ParamSpec("reactive", bool, "Reactive agents (passiveness ~ U{2..6}) or not (n_pass = 0).", "n_pass",
              "§III-B, §VI-B", default=True),
    ParamSpec("autostart", bool, "Start the first episode at launch (else wait for the reset service).",
              default=True),
    ParamSpec("scenario.family", str, "Scenario family: 'paper' (the §VI-A protocol: 1-2 dynamic vehicles, contested "
              "spots) or 'busy' (20+ parking and exiting cars, 10+ pedestrians, spots freeing and filling; "
              "avp_sim/core/busy.py; beyond the paper, whose §VII names these as its limits).", "", "§VI-A, §VII",
              choices=("paper", "busy"), default="paper"),
    ParamSpec("busy.occupancy_min", float, "busy: least share of spots taken at the start.", "", "",
              min=0.0, max=1.0, default=0.75),
    ParamSpec("busy.occupancy_max", float, "busy: largest such share.", "", "", min=0.0, max=1.0, default=0.9),
    ParamSpec("busy.arrival_gap_min", float, "busy: least mean gap between cars arriving at the gate (drawn per "
              "episode).", "", "", min=0.5, max=600.0, default=2.0),
    ParamSpec("busy.arrival_gap_max", float, "busy: largest such mean gap.", "", "", min=0.5, max=600.0,
              default=4.0),
    ParamSpec("busy.departure_gap_min", float, "busy: least mean gap between cars leaving their spots.", "", "",
              min=0.5, max=600.0, default=3.0),
    ParamSpec("busy.departure_gap_max", float, "busy: largest such mean gap.", "", "", min=0.5, max=600.0,
              default=6.0),
    ParamSpec("busy.n_pedestrians_min", int, "busy: fewest pedestrians (eq. 2) walking between the gate and cars.",
              "", "§II-C", min=0, max=200, default=10),
    ParamSpec("busy.n_pedestrians_max", int, "busy: most pedestrians.", "", "§II-C", min=0, max=200, default=16),
    ParamSpec("scenario.passiveness_min", int, "Smallest passiveness in reactive mode.", "n_pass", "§VI-B",
              min=0, max=100, default=2),
    ParamSpec("scenario.passiveness_max", int, "Largest passiveness in reactive mode.", "n_pass", "§VI-B",
              min=0, max=100, default=6),
    ParamSpec("scenario.passiveness_step", float, "Seconds per unit of passiveness: an agent brakes if its plan "
              "over the next n_pass units meets the ego. §III-B counts timesteps; 0.1 = the simulator's Δt, 0.5 = "
              "Nawaz et al.'s timestep (protocol 'paper', docs/experiment.md).", "n_pass", "§III-B, §VI-A",
              min=0.01, max=5.0, default=0.1),
    ParamSpec("scenario.n_dynamic_min", int, "Fewest dynamic vehicles.", "", "§VI-A", min=0, max=10, default=1),
    ParamSpec("scenario.n_dynamic_max", int, "Most dynamic vehicles.", "", "§VI-A", min=0, max=10, default=2),
    ParamSpec("scenario.outer_row_min", int, "First row of each fallback group (the lot's, from the far end of the "
              "ego's road; paper lot: the outer columns, 0 = bottom) from which the 2 vacant fallback spots are drawn "
              "(docs/world.md; 0..9 = anywhere on the paper lot).", "", "§VI-A", min=0, max=999, default=0),
    ParamSpec("scenario.outer_row_max", int, "Last such row (default: the contested spots' rows 0..4).", "",
              "§VI-A", min=0, max=999, default=4),
    ParamSpec("scenario.maneuver_max_speed", float, "Speed bound of the dynamic vehicles' parking maneuvers "
              "(ParkSim's 8); 1.1 m/s gives ParkSim's pace, 1 s per metre (docs/world.md); 2.0 = earlier reading.",
              "", "§VI-A", min=0.1, max=5.0, default=1.1),
    ParamSpec("scenario.approach_distance_min", float, "Least distance a dynamic vehicle still drives in its lane to "
              "its maneuver's start at t = 0 (drawn uniformly).", "", "§VI-A", min=0.0, max=100.0, default=0.0),
    ParamSpec("scenario.approach_distance_max", float, "Largest such distance (the competition-intensity knob of "
              "docs/experiment.md).", "", "§VI-A", min=0.0, max=100.0, default=8.0),
    ParamSpec("scenario.cruise_speed_min", float, "Least lane speed of a dynamic vehicle before it brakes for its "
              "maneuver.", "", "§VI-A", min=0.1, max=5.0, default=1.5),
    ParamSpec("scenario.cruise_speed_max", float, "Largest such speed.", "", "§VI-A", min=0.1, max=5.0,
              default=2.5),
    ParamSpec("scenario.spawn_closer_than_ego", bool, "Re-draw a dynamic vehicle whose centre at t = 0 is not nearer "
              "its target spot than the ego's start (§VI-B: agents 'initialized closer to their intended spots').",
              "", "§VI-B", default=False),
    ParamSpec("agents_yield", bool, "Agents also brake for each other by §III-B's rule, with their own n_pass: a "
              "car for a car or pedestrian its next n_pass footprints meet, a pedestrian for a moving car "
              "(avp_sim/core/agent_yield.py). §III-B: agents react to the ego only (false, the paper); on the busy "
              "lot they then drive through each other.", "n_pass", "§III-B", default=False),
    ParamSpec("egos.count", int, "Automated cars (egos) in the lot, each with its own observation, command and "
              "metrics (avp_sim/core/egos.py; a scenario file's `egos` sets them instead). The paper has one; with "
              "more, §III-B's agents brake for every ego (a departure).", "K", "", min=1, max=8, default=1),
    ParamSpec("egos.entry_interval", float, "Seconds between two egos' entries through the gate (each enters once "
              "its time has come and the gate is clear; its parking time counts from its entry).", "", "",
              min=0.0, max=600.0, default=5.0),
    ParamSpec("egos.entry_clearance", float, "The gate is clear for the next ego or driven car only when no vehicle "
              "or ego comes within this distance of its start footprint (0: only an overlap blocks it, and a car "
              "may appear touching the one ahead).", "", "", min=0.0, max=10.0, default=1.0),
    ParamSpec("drivers.count", int, "Cars a person drives (docs/teleop.md): their controls come from "
              "driver<j>/cmd_vel (geometry_msgs/Twist, or TwistStamped with drivers.stamped), clamped to eq. (1)'s "
              "limits. Not in the paper. Needs mode realtime (lock-step never waits for a person).", "", "", min=0,
              max=4, default=0),
    ParamSpec("drivers.enter_at", float, "Seconds into the episode when the first driven car may enter through the "
              "gate (it enters once the gate is clear; the next ones egos.entry_interval apart).", "", "", min=0.0,
              max=600.0, default=0.0),
    ParamSpec("drivers.poses", str, "Where the driven cars enter: 'x,y,theta' for each, separated by ';' ('' = the "
              "gate, as the egos).", "", "", default=""),
    ParamSpec("drivers.watchdog", float, "A driver's command older than this (wall seconds) stops the car: a lost "
              "connection never leaves it driving.", "", "", min=0.01, max=10.0, default=0.5),
    ParamSpec("drivers.stamped", bool, "Take geometry_msgs/TwistStamped on driver<j>/cmd_vel (teleop_twist_keyboard "
              "stamped:=true) instead of Twist (Foxglove's Teleop panel, teleop_twist_keyboard's default).",
              default=False),
    ParamSpec("ego_max_speed", float, "Ego speed limit; commands are clipped to it and to |ω| <= |v|/R_min.",
              "v", "eq. (1)", min=0.0, default=5.0),
    ParamSpec("auth_inputs", bool, "Take only commands tagged with the user's key (avp_common.msg_auth, "
              "$AVP_CMD_KEY_FILE); others are dropped and their publishers named. Outputs are always tagged.",
              default=True),
    ParamSpec("scenario_dir", str, "A directory whose scenario files reset_episode may serve besides the bundled "
              "config/scenarios ('' = none); a path outside them is refused unread (docs/bad_input.md).",
              default=""),
    ParamSpec("scenario_max_bytes", int, "Largest scenario (file or scenario_yaml text) reset_episode reads.",
              min=1, max=100_000_000, default=1_000_000),
    ParamSpec("lockstep_timeout", float, "Lock-step: wall seconds without a matching command before the "
              "observation is re-sent with a warning.", min=0.05, default=5.0),
    ParamSpec("command_watchdog", float, "Real-time: a command older than this (wall seconds) is ignored and "
              "the ego holds still.", min=0.0, default=0.3),
    ParamSpec("command_max_lag", int, "Real-time: a command answering an observation more than this many steps "
              "old is ignored and the ego holds still (0: only the current one; a dead pipeline node stops the ego "
              "within one step).", min=0, max=1000, default=0),
    ParamSpec("realtime_wait_first_command", bool, "Real-time: the clock starts when the ego's pipeline is up — "
              "step 0 (observation and ground truth) is re-sent every step period until a command answering it "
              "arrives (false: the world runs from the first observation; the ego holds still until its nodes are "
              "ready, e.g. while the belief node prepares a big lot).", default=True),
    ParamSpec("wait_for_subscribers", bool, "Lock-step: hold step 0 until a subscriber to observation and a "
              "publisher on cmd exist, then 0.5 s more the first time (sim_node.SUBSCRIBER_SETTLE_S: the "
              "readers finish matching).", default=True),
    ParamSpec("min_subscribers", int, "Lock-step: step 0 waits for this many observation subscribers (the ego "
              "pipeline, plus recorders/monitors that must see step 0).", min=1, max=100, default=1),
    ParamSpec("min_debug_subscribers", int, "Lock-step: step 0 also waits for this many debug/ground_truth "
              "subscribers (monitors and recorders that must not miss a step).", min=0, max=100, default=0),
    ParamSpec("publish_markers", bool, "Publish debug/markers (MarkerArray) and debug/scan (LaserScan), each "
              "built only while it has a subscriber (a viewer or a recorder).",
              default=True),
]

#: the sensing model (avp_sensing.noisy; docs/perception.md, "Sensing"): beyond the paper, whose §III-A assumes
#: "the ego correctly observes every spots and agents it senses" and leaves noisy observations as future work
SIM_PARAMS += [
    ParamSpec("sensing.model", str, "exact: the paper's observation (every id, exact history, exact spots); "
              "realistic / harsh: noisy detections without ids or histories, a localisation estimate, misread spots "
              "(presets, docs/perception.md); custom: the sensing.* values below (their defaults: realistic).", "",
              "§III-A", choices=_sensing.MODELS, default="exact"),
    *(ParamSpec(f"sensing.{f}", float, _sensing.DESCRIPTIONS[f], "", "§III-A", min=0.0,
                max=1.0 if f in _sensing.PROBABILITIES else None, default=getattr(_sensing.REALISTIC, f))
      for f in _sensing.FIELDS),
]

_ = math  # (symbols documented above)

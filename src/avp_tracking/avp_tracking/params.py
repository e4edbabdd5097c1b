"""Parameters of the tracker node and of the in-process tracker (config/tracker.param.yaml); beyond the paper, whose
§III-A gives the ego every vehicle's exact history (docs/perception.md, "Tracking")."""

from __future__ import annotations

from avp_common.params import ParamSpec
from avp_tracking.core.motion import MotionNoise
from avp_tracking.core.tracker import TrackerConfig

_D = TrackerConfig()
_N = MotionNoise()
_WHY = "§III-A"

TRACKER_PARAMS: list[ParamSpec] = [
    ParamSpec("tracking.gate", float, "Squared Mahalanobis gate of a track-detection pairing (chi-square, 2 dof; "
              "11.62 = 99.7 %, Autoware's multi_object_tracker).", "", _WHY, min=0.1, default=_D.gate),
    ParamSpec("tracking.max_distance", float, "Largest centre distance of a vehicle pairing [m].", "", _WHY,
              min=0.1, default=_D.max_distance),
    ParamSpec("tracking.pedestrian_max_distance", float, "Largest distance of a pedestrian pairing [m].", "", _WHY,
              min=0.1, default=_D.pedestrian_max_distance),
    ParamSpec("tracking.n_init", int, "Hits that confirm a track (a tentative track dies at its first miss).", "",
              _WHY, min=1, max=100, default=_D.n_init),
    ParamSpec("tracking.max_coast", float, "Seconds a confirmed track lives unseen (coasted on its motion model).",
              "", _WHY, min=0.0, max=60.0, default=_D.max_coast),
    ParamSpec("tracking.coast_deceleration", float, "Rate at which an unseen vehicle track's speed brakes to 0 while "
              "it coasts [m/s^2]; 0 = off (it coasts at its last speed).", "", _WHY, min=0.0, max=20.0,
              default=_D.coast_deceleration),
    ParamSpec("tracking.flip_votes", float, "Detections, net, with the heading turned by pi that turn a track "
              "around.", "", _WHY, min=1.0, max=100.0, default=_D.flip_votes),
    ParamSpec("tracking.size_smoothing", float, "Weight of a new box's length and width in the track's.", "", _WHY,
              min=0.0, max=1.0, default=_D.size_smoothing),
    ParamSpec("tracking.static_speed", float, "A track standing in a spot slower than this is static (K_sv) [m/s].",
              "K_sv", _WHY, min=0.0, default=_D.static_speed),
    ParamSpec("tracking.prune_distance", float, "Of two vehicle tracks closer than this whose axes agree within 30 "
              "degrees, the one with fewer hits is dropped (a duplicate); 0 = never [m].", "", _WHY, min=0.0,
              default=_D.prune_distance),
    ParamSpec("tracking.stationary_after", float, "Seconds a vehicle track stays slower than static_speed before "
              "it is held stationary (its process noise scaled by stationary_noise_scale).", "", _WHY, min=0.0,
              default=_D.stationary_after),
    ParamSpec("tracking.stationary_noise_scale", float, "A stationary track's process noise (variances) times the "
              "moving one's; 1 = no stationary mode.", "", _WHY, min=0.0, max=1.0, default=_D.stationary_noise_scale),
    ParamSpec("tracking.stationary_hold", float, "A stationary track's pose and box as given to the ego change only "
              "when its estimate has moved by more than this (the planner's static world stays the same while a "
              "parked car stands); 0 = the estimate every step [m].", "", _WHY, min=0.0,
              default=_D.stationary_hold),
    ParamSpec("tracking.stationary_hold_heading", float, "The same for a stationary track's heading [rad].", "",
              _WHY, min=0.0, default=_D.stationary_hold_heading),
    ParamSpec("tracking.spot_misread_far", float, "A spot reading's error probability at spot_reach, as the ego "
              "knows its sensor (growing as range^2; sensing.spot_misread_far is the simulated truth): each seen "
              "spot is reported by its readings' log-odds, not this step's reading alone; 0 = the reading as it "
              "comes (eq. 7's input unfiltered).", "", _WHY, min=0.0, max=0.49, default=_D.spot_misread_far),
    ParamSpec("tracking.spot_reach", float, "The range at which a spot reading's error is spot_misread_far (the "
              "sensing region's reach) [m].", "", _WHY, min=0.1, default=_D.spot_reach),
    ParamSpec("tracking.spot_max_log_odds", float, "A spot's evidence is clamped to +- this many nats, so a spot "
              "that really changes (a car parks or leaves) is followed within a few readings.", "", _WHY, min=0.1,
              default=_D.spot_max_log_odds),
    ParamSpec("tracking.near_hold_radius", float, "A confirmed vehicle track unseen longer than max_coast whose centre "
              "is this near the ego's estimate is kept standing (speed 0) until seen again, the ego leaves the "
              "radius, a ray passes through its centre, or near_hold_max; 0 = off (dropped) [m].", "", _WHY,
              min=0.0, max=50.0, default=_D.near_hold_radius),
    ParamSpec("tracking.near_hold_max", float, "Seconds beyond max_coast a track is kept standing near the ego.",
              "", _WHY, min=0.0, max=120.0, default=_D.near_hold_max),
    ParamSpec("tracking.box_sigmas", float, "A moving vehicle track's box, as given to the ego, grows by this many "
              "standard deviations of its position estimate at each side (a coasted track's covers where the car "
              "may be); stationary tracks are not grown; 0 = off.", "", _WHY, min=0.0, max=10.0,
              default=_D.box_sigmas),
    ParamSpec("tracking.pedestrian_velocity", str, "The previous position given with a pedestrian track, from which "
              "the ego reads its velocity (§V-C: v = (p_t - p_t-dt) / dt): difference = the track's estimate one "
              "step before (each step's correction jump reads as motion: a standing pedestrian seems to walk); "
              "filter = the estimate minus the filter's velocity times dt.", "", "§V-C",
              choices=("difference", "filter"), default=_D.pedestrian_velocity),
    ParamSpec("tracking.static_until_moved", float, "A vehicle track inside a spot is given to the ego as static "
              "(no intentions, no prediction) until its estimate has once been this far from where it was born: a "
              "parked car newly seen starts with a noisy speed; 0 = off (static only when slower than "
              "static_speed) [m].", "", "§V-A", min=0.0, max=10.0, default=_D.static_until_moved),
    ParamSpec("tracking.history_smoothing", str, "A moving vehicle track's history as given to the ego: none = the "
              "filter's estimates step by step (each correction jump reads as a change of speed); rts = its last "
              "smoothing_lag poses smoothed by a fixed-lag Rauch-Tung-Striebel smoother.", "", _WHY,
              choices=("none", "rts"), default=_D.history_smoothing),
    ParamSpec("tracking.smoothing_lag", int, "Poses of a moving track's history the smoother revises.", "", _WHY,
              min=2, max=200, default=_D.smoothing_lag),
    ParamSpec("tracking.publish_coasted", bool, "Give the ego coasted (occluded) confirmed tracks too, not only "
              "those detected this step.", "", _WHY, default=_D.publish_coasted),
    ParamSpec("tracking.accel_sigma", float, "Process noise: a vehicle's longitudinal acceleration [m/s^2].", "",
              _WHY, min=0.0, default=_N.accel_sigma),
    ParamSpec("tracking.yaw_accel_sigma", float, "Process noise: its yaw acceleration [rad/s^2].", "", _WHY,
              min=0.0, default=_N.yaw_accel_sigma),
    ParamSpec("tracking.lateral_sigma", float, "Process noise: lateral velocity the CTRV model misses [m/s].", "",
              _WHY, min=0.0, default=_N.lateral_sigma),
    ParamSpec("tracking.pedestrian_accel_sigma", float, "Process noise: a pedestrian's acceleration [m/s^2].", "",
              _WHY, min=0.0, default=_N.pedestrian_accel_sigma),
]

#: the node's own parameters (its inputs and outputs)
NODE_PARAMS: list[ParamSpec] = [
    ParamSpec("sync", str, "stamp: frame k waits for the detections stamped t_k (lock-step); latest: the newest "
              "detections received within max_detection_age (a real detector on its own clock).",
              choices=("stamp", "latest"), default="stamp"),
    ParamSpec("detection_wait", float, "sync stamp: wall seconds a frame waits for its detections before it is "
              "answered without them (the tracks coasted).", min=0.0, default=1.0),
    ParamSpec("max_detection_age", float, "sync latest: detections older than this (wall seconds) are not used.",
              min=0.0, default=0.5),
    ParamSpec("max_objects", int, "A DetectedObjects message with more objects is refused whole.", min=1,
              max=100000, default=1000),
    ParamSpec("auth_inputs", bool, "Only frames and the lot map tagged with the user's key are read "
              "(docs/bad_input.md).", default=True),
    ParamSpec("auth_detections", bool, "Only tagged detections are read (the simulator tags its own); false for "
              "a real detector that does not sign (docs/perception.md).", default=True),
    ParamSpec("min_subscribers", int, "Hold an answer until observation has this many subscribers (the ego's "
              "nodes, and the viewers that must see step 0).", min=0, max=100, default=3),
    ParamSpec("t_hist", float, "History length given for every track (the simulator's t_hist).", "t_hist",
              "§III-A", min=0.0, max=20.0, default=4.0),
]
#: everything config/tracker.param.yaml holds
TRACKER_NODE_PARAMS = [*TRACKER_PARAMS, *NODE_PARAMS]


def tracker_config(values: dict, dt: float = 0.1, t_hist: float = 4.0) -> TrackerConfig:
    """The tracker's settings of validated parameter ``values``; its history is the simulator's t_hist / dt + 1."""
    v = {k.split(".", 1)[1]: val for k, val in values.items() if k.startswith("tracking.")}
    noise = MotionNoise(accel_sigma=v["accel_sigma"], yaw_accel_sigma=v["yaw_accel_sigma"],
                        lateral_sigma=v["lateral_sigma"], pedestrian_accel_sigma=v["pedestrian_accel_sigma"])
    return TrackerConfig(gate=v["gate"], max_distance=v["max_distance"],
                         pedestrian_max_distance=v["pedestrian_max_distance"], n_init=v["n_init"],
                         max_coast=v["max_coast"], coast_deceleration=v["coast_deceleration"],
                         flip_votes=v["flip_votes"], size_smoothing=v["size_smoothing"],
                         history_steps=int(round(t_hist / dt)) + 1, static_speed=v["static_speed"],
                         publish_coasted=v["publish_coasted"], noise=noise,
                         prune_distance=v["prune_distance"], stationary_after=v["stationary_after"],
                         stationary_noise_scale=v["stationary_noise_scale"],
                         stationary_hold=v["stationary_hold"],
                         stationary_hold_heading=v["stationary_hold_heading"],
                         spot_misread_far=v["spot_misread_far"], spot_reach=v["spot_reach"],
                         spot_max_log_odds=v["spot_max_log_odds"], near_hold_radius=v["near_hold_radius"],
                         near_hold_max=v["near_hold_max"], box_sigmas=v["box_sigmas"],
                         pedestrian_velocity=v["pedestrian_velocity"], history_smoothing=v["history_smoothing"],
                         smoothing_lag=v["smoothing_lag"], static_until_moved=v["static_until_moved"])


def default_tracker_values() -> dict:
    """The shipped config/tracker.param.yaml's values (the specs' defaults)."""
    return {s.name: s.default for s in TRACKER_PARAMS}

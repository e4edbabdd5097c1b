"""How an agent's motion reads through the tracker (docs/results/sensing/README.md): scripted detections of one
agent with Gaussian noise, and the speed the planner reads from the two last positions it is given (§V-C for a
pedestrian; a vehicle's last two history poses, as avp_motion/trace.py and the yield rule read them) against the
tracker's filter.

    python tools/motion_from_tracks.py [--steps 400] [--seed 0]

Prints, per agent, speed and noise: the median and 90th percentile of the speed error read from two positions and
of the filter's, the share of steps a standing pedestrian reads as moving (faster than 0.3 m/s) and the share a
steady car reads as braking (0.3 m/s slower than 0.5 s before).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from avp_tracking.core.perceive import TrackingPerception
from avp_tracking.core.tracker import Tracker, TrackerConfig
from avp_world.detections import PedestrianDetection, SensedFrame, VehicleDetection
from avp_world.lot import load_bundled_lot

DT = 0.1
STILL = 0.3  # m/s, avp_motion.planner_types.STILL_SPEED
BRAKING_DROP, BRAKING_STEPS = 0.3, 5  # avp_motion.trace: 0.3 m/s lost over 0.5 s


def _frame(k: int, vehicles=(), pedestrians=()) -> SensedFrame:
    return SensedFrame(step=k, dt=DT, ego_pose=np.zeros(3), ego_covariance=np.eye(3) * 1e-4, ego_length=4.5,
                       ego_width=1.9, ego_speed=0.0, vacant_spot_ids=np.zeros(0, np.int64),
                       occupied_spot_ids=np.zeros(0, np.int64), vehicles=tuple(vehicles),
                       pedestrians=tuple(pedestrians))


def run(kind: str, speed: float, sigma: float, mode: str, steps: int, seed: int) -> dict:
    """One agent moving along x at ``speed``, detected 90 % of steps with ``sigma`` noise."""
    rng = np.random.default_rng(seed)
    cfg = TrackerConfig(pedestrian_velocity=mode) if kind == "pedestrian" else TrackerConfig(history_smoothing=mode)
    p = TrackingPerception(load_bundled_lot(), Tracker(cfg))
    two, filt, flagged = [], [], []
    for k in range(steps):
        xy = np.array([speed * DT * k, -30.0]) + rng.normal(0.0, sigma, 2)
        seen = rng.random() < 0.9
        if kind == "pedestrian":
            dets = [PedestrianDetection(position=xy, radius=0.3, covariance=np.eye(2) * sigma ** 2,
                                        existence=0.9)] if seen else []
            obs = p.observe(_frame(k, pedestrians=dets))
        else:
            dets = [VehicleDetection(pose=np.array([*xy, 0.0]), length=4.5, width=1.9,
                                     covariance=np.diag([sigma ** 2, sigma ** 2, 0.05 ** 2]), existence=0.9,
                                     speed=speed + rng.normal(0.0, 0.26), speed_variance=0.26 ** 2)] if seen else []
            obs = p.observe(_frame(k, vehicles=dets))
        if k < 60:
            continue
        t = p.tracker.tracks_given[0]
        if kind == "pedestrian":
            ped = obs.pedestrians[0]
            s = float(np.hypot(*(ped.position - ped.previous_position))) / DT
            flagged.append(s > STILL if speed == 0 else False)
            filt.append(abs(float(np.hypot(*t.x[2:4])) - speed))
        else:
            h = obs.vehicles[0].history
            s = float(np.hypot(*(h[-1, :2] - h[-2, :2]))) / DT
            before = float(np.hypot(*(h[-1 - BRAKING_STEPS, :2] - h[-2 - BRAKING_STEPS, :2]))) / DT
            flagged.append(s >= STILL and before - s > BRAKING_DROP)
            filt.append(abs(abs(t.speed) - speed))
        two.append(abs(s - speed))
    return {"two": _quantiles(two), "filter": _quantiles(filt), "flagged": float(np.mean(flagged))}


def _quantiles(a: list[float]) -> str:
    return f"{np.median(a):.2f} / {np.percentile(a, 90):.2f}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    print("| agent | speed (m/s) | noise (m) | `pedestrian_velocity` / `history_smoothing` | speed error from two "
          "positions, median / p90 | "
          "filter's | steps read as moving (pedestrian at rest) or braking (car) |")
    print("|---|--:|--:|---|--:|--:|--:|")
    for kind, speed, sigma, mode in (("pedestrian", 0.0, 0.15, "difference"), ("pedestrian", 0.0, 0.15, "filter"),
                                     ("pedestrian", 1.0, 0.15, "difference"), ("pedestrian", 1.0, 0.15, "filter"),
                                     ("car", 0.0, 0.1, "none"), ("car", 2.0, 0.1, "none"), ("car", 2.0, 0.1, "rts"),
                                     ("car", 2.0, 0.2, "none"), ("car", 2.0, 0.2, "rts")):
        r = run(kind, speed, sigma, mode, a.steps, a.seed)
        print(f"| {kind} | {speed} | {sigma} | {mode} | {r['two']} | {r['filter']} "
              f"| {100 * r['flagged']:.0f} % |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

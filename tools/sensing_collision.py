"""What the ego saw of the car it hit: one episode of a noisy-sensing run re-run in process (docs/results/sensing).

    python tools/sensing_collision.py OUT SEED CAR|boundary [--steps 25] [--method bezier] [--mode reactive]

OUT is the run's folder (its run.json gives the settings; the episode is the reactive one of SEED), CAR the
simulator id the record's ``collision_with`` names (``vehicle:CAR``). For each of the last ``--steps`` steps: the
distance from the ego to the car, the ego's true and estimated pose, the car's true pose, the ego's mode and
command, and every track that follows the car (its pose, whether it is held static, its misses in a row), or
"not tracked". With ``boundary`` for CAR (``collision_with: boundary``): the distance from the ego's footprint to the
lot's walls at its true pose and at its estimate instead. The truth is read for this report only; the ego sees what
it saw in the run.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from shapely.geometry import LinearRing, Polygon

from avp_episode.ego import MethodEgo
from avp_episode.run_config import run_profile, sim_values, tracker_values
from avp_episode.sensing import sensed_observer, truth_ids
from avp_experiment.failures import _config
from avp_sim.core.factory import load_lot_param, make_world
from avp_world.geometry import rect_corners


def replay(out: Path, seed: int, car: int | None, method: str = "bezier", reactive: bool = True
           ) -> tuple[str, list[str]]:
    """The episode's status and one line a step (module docstring); ``car`` None: the lot boundary."""
    cfg = _config(out)
    sim_p = sim_values(cfg)
    lot = load_lot_param(sim_p["lot_file"])
    world = make_world(lot, sim_p, seed, reactive)
    observe = sensed_observer(world, sim_p, seed, tracker_values(cfg))
    if observe is None:
        raise SystemExit(f"{out}: exact sensing; nothing to replay here")
    ego = MethodEgo(lot, run_profile(method, cfg), deterministic=True, intent_weights=cfg.intent_weights,
                    intent_seed=cfg.intent_seed, message_precision=cfg.message_precision)
    row = int(np.nonzero(world.vehicle_ids == car)[0][0]) if car is not None else -1
    walls = LinearRing(lot.boundary)
    lines, k = [], 0
    while not world.done:
        obs = observe()
        ids = truth_ids(world, obs)
        step = ego.step(obs)
        misses = {int(t.id): t.misses for t in observe.tracker.tracks}
        seen = [f"track {v.id} at {np.round(v.pose, 2)} static={v.is_static} misses={misses.get(int(v.id))}"
                for v in obs.vehicles if ids.get(int(v.id)) == car]
        mode = step.decision.mode if step.decision is not None else "-"
        if car is None:
            d_true, d_est = (Polygon(rect_corners(np.asarray(p[:3], float)[None], obs.ego_length, obs.ego_width)[0])
                             .distance(walls) for p in (world.ego, obs.ego_pose))
            lines.append(f"k={k} to the walls {d_true:.2f} m (estimate {d_est:.2f} m) ego={np.round(world.ego[:3], 2)} "
                         f"estimate={np.round(obs.ego_pose, 2)} {mode} cmd={np.round(step.command, 2)}")
            world.step(*step.command)
            k += 1
            continue
        d = float(np.hypot(*(world.states[row, :2] - world.ego[:2])))
        lines.append(f"k={k} d={d:.2f} m ego={np.round(world.ego[:3], 2)} estimate={np.round(obs.ego_pose, 2)} "
                     f"car={np.round(world.states[row, :3], 2)} {mode} cmd={np.round(step.command, 2)} | "
                     + ("; ".join(seen) or "not tracked"))
        world.step(*step.command)
        k += 1
    return f"{world.status} after {k} steps", lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path)
    ap.add_argument("seed", type=int)
    ap.add_argument("car", help="the simulator id of the car hit, or boundary")
    ap.add_argument("--steps", type=int, default=25)
    ap.add_argument("--method", default="bezier")
    ap.add_argument("--mode", choices=("reactive", "non-reactive"), default="reactive")
    args = ap.parse_args(argv)
    car = None if args.car == "boundary" else int(args.car)
    status, lines = replay(args.out, args.seed, car, args.method, args.mode == "reactive")
    print(status)
    print("\n".join(lines[-args.steps:]))
    return 0


if __name__ == "__main__":
    sys.exit(main())

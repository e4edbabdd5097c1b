"""Who the ego "stole" a spot from on the busy lot: for each stolen episode of a records file, the car(s)
heading for the spot the ego parked in — had it started its plan when the ego parked, how far from the spot it
started, and (``--ego``) whether the ego had ever observed it before choosing the spot.

    python tools/stolen_spots.py RECORDS.jsonl[:METHOD] [...] [--ego] [--json OUT.jsonl]

§VI-B counts a spot as stolen when the ego parks in a spot a dynamic vehicle was heading for, and reads every such
case as stealing because "all dynamic agents were initialized closer to their intended spots". On the busy family
that premise does not hold: cars enter through the gate during the episode. This tool splits the count. Without
``--ego`` it reads only the simulator's scenario (same seed ⇒ same scenario) and the records; with ``--ego`` it
re-runs each stolen episode (the records' method, reactive mode, the shipped parameters plus KEY=VALUE given with
``--planner-param``) and reports the first step the ego had a prediction of the car, against the first step it
planned to the spot. The re-run must give the record's parked spot and step, or the line says so.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))


def heading_for(world, lot, spot_id: int, steps: int) -> list[dict]:
    """The dynamic vehicles of ``world`` whose target is ``spot_id``: id, the step their plan starts (relative to
    the ego's t = 0), whether that is before ``steps`` (the ego's parking step), and their distance to the spot at
    the start."""
    out = []
    sx, sy = lot.spot_poses[lot.spot_index(spot_id)][:2]
    for i in np.nonzero(world.is_dynamic & (world.target_spot == spot_id))[0]:
        moving = np.nonzero(np.abs(world.plans[i, :, 0]) > 0)[0]
        start = int(moving[0]) - world.hist if len(moving) else None
        out.append({"id": int(world.vehicle_ids[i]), "plan_start_step": start,
                    "started": start is not None and start < steps,
                    "start_distance_m": round(float(np.hypot(world.states[i][0] - sx, world.states[i][1] - sy)), 1)})
    return out


def _ego_view(lot, sim: dict, cfg, method: str, seed: int, spot_id: int) -> dict:
    """Re-run the episode as the runner does (:func:`avp_episode.episodes.run_episode_inproc`): the first step
    the ego planned to ``spot_id`` and, per car, the first step it had a prediction of it."""
    from avp_episode.episodes import run_episode_inproc
    from avp_episode.run_config import run_profile

    first_aim, seen = None, {}

    def watch(_world, out) -> None:
        nonlocal first_aim
        if first_aim is None and out.decision.mode == "park" and int(out.decision.spot_id) == spot_id:
            first_aim = out.step
        for p in out.predictions:
            if not p.is_pedestrian:
                seen.setdefault(int(p.agent_id), out.step)

    record = run_episode_inproc(lot, sim, run_profile(method, cfg), seed, True, cfg, on_step=watch)
    return {"first_aim_step": first_aim, "first_seen": seen, "parked": int(record["parked_spot_id"]),
            "steps": int(record["steps"])}


def main(argv: list[str]) -> int:
    from probe_episodes import run_config

    from avp_episode.run_config import sim_values
    from avp_experiment.results import open_records
    from avp_sim.core.factory import load_lot_param, make_world

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("records", nargs="+", metavar="RECORDS[:METHOD]")
    ap.add_argument("--ego", action="store_true", help="re-run each stolen episode to see what the ego observed")
    ap.add_argument("--planner-param", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--t-final", type=float, default=60.0)
    ap.add_argument("--json", help="append one line per stolen episode to this file")
    a = ap.parse_args(argv)
    cfg = run_config(a.t_final, a.planner_param)
    sim = sim_values(cfg)
    lot = load_lot_param(sim["lot_file"])
    for spec in a.records:
        path, _, method = spec.partition(":")
        with open_records(path) as lines:  # .jsonl or .jsonl.gz
            recs = [json.loads(line) for line in lines if line.strip()]
        recs = [r for r in recs if r["mode"] == "reactive" and (not method or r["method"] == method)]
        stolen = [r for r in recs if r["spot_stolen"]]
        counts = {"started": 0, "not_started": 0, "seen_before_aim": 0, "never_seen": 0, "seen_after_aim": 0}
        for r in stolen:
            world = make_world(lot, sim, r["seed"], True)
            cars = heading_for(world, lot, int(r["parked_spot_id"]), int(r["steps"]))
            line = {"path": path, "method": r["method"], "seed": r["seed"], "parked": r["parked_spot_id"],
                    "steps": r["steps"], "cars": cars}
            counts["started" if any(c["started"] for c in cars) else "not_started"] += 1
            if a.ego:
                view = _ego_view(lot, sim, cfg, r["method"], r["seed"], int(r["parked_spot_id"]))
                line["rerun_equal"] = view["parked"] == r["parked_spot_id"] and view["steps"] == r["steps"]
                line["first_aim_step"] = view["first_aim_step"]
                for c in cars:
                    c["first_seen_step"] = view["first_seen"].get(c["id"])
                aim = view["first_aim_step"]
                seen = [c["first_seen_step"] for c in cars if c["first_seen_step"] is not None]
                key = ("never_seen" if not seen else
                       "seen_before_aim" if aim is not None and min(seen) <= aim else "seen_after_aim")
                counts[key] += 1
            print(json.dumps(line), flush=True)
            if a.json:
                with open(a.json, "a") as f:
                    f.write(json.dumps(line) + "\n")
        shown = {k: v for k, v in counts.items() if a.ego or k in ("started", "not_started")}
        print(f"# {path}{':' + method if method else ''}: {len(recs)} reactive episodes, {len(stolen)} stolen; "
              f"the car heading for the spot {shown}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

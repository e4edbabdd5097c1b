"""Why the ego's driven plans are dropped: episodes of a results folder re-run in process, counting each plan the
planner drops by the reason its re-check gives (§V-D: off the plan, a static obstacle or a predicted agent on it, an
exploration plan nearly done), with each episode's outcome, steps, reversals and spot switches (a parking plan to
another spot than the last parking plan's) (docs/results/sensing/README.md).

    python tools/plan_drops.py OUT SEEDS [--sensing exact] [--planner-param KEY=VALUE ...]
        [--tracker-param KEY=VALUE ...] [--method bezier] [--mode reactive]

OUT is a run's folder (its run.json gives the settings; each seed's episode in ``--mode``, reactive unless told:
`contested` is non-reactive), SEEDS a comma list or a range a-b. ``--sensing exact`` runs the same episodes with
the paper's exact sensor; ``--planner-param`` overrides a planner value and ``--tracker-param`` a tracker value (as
``avp experiment`` does).
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

from avp_episode.ego import MethodEgo
from avp_episode.run_config import run_profile, sim_values, tracker_values
from avp_episode.sensing import sensed_observer
from avp_experiment.failures import _config
from avp_experiment.runner import parse_planner_params, parse_tracker_params
from avp_planner.core.decision import EgoPlanner
from avp_sim.core.factory import load_lot_param, make_world


def seeds_of(text: str) -> list[int]:
    """``1,5,9`` or ``0-19``."""
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(s) for s in text.split(",")]


def run(out: Path, seeds: list[int], exact: bool = False, overrides: dict | None = None, method: str = "bezier",
        tracker: dict | None = None, reactive: bool = True
        ) -> tuple[list[tuple[int, str, int, int, int]], Counter, Counter]:
    """([(seed, status, steps, reversals, spot switches)], drops by "mode: reason", switches by what the last
    target spot was at the switch: not seen vacant, believed taken (b_t > δ as the planner received it), or still a
    candidate)."""
    cfg = _config(out)
    cfg.planner_overrides.update(overrides or {})
    cfg.tracker_overrides.update(tracker or {})
    sim_p = dict(sim_values(cfg))
    if exact:
        sim_p["sensing.model"] = "exact"
    lot = load_lot_param(sim_p["lot_file"])
    drops: Counter = Counter()
    causes: Counter = Counter()
    original = EgoPlanner._still_valid

    def counted(self, plan, ego, world, dyn):
        ok, why = original(self, plan, ego, world, dyn)
        if not ok:
            drops[f"{plan.mode}: {why}"] += 1
        return ok, why

    EgoPlanner._still_valid = counted
    rows = []
    try:
        for seed in seeds:
            world = make_world(lot, sim_p, seed, reactive)
            observe = sensed_observer(world, sim_p, seed, tracker_values(cfg)) or world.observe
            ego = MethodEgo(lot, run_profile(method, cfg), deterministic=True, intent_weights=cfg.intent_weights,
                            intent_seed=cfg.intent_seed, message_precision=cfg.message_precision)
            last, reversals, k, spot, switches = 0.0, 0, 0, -1, 0
            delta = ego.planner.settings.decision.candidate_threshold
            while not world.done:
                obs = observe()
                step = ego.step(obs)
                if step.decision.mode == "park":
                    if spot >= 0 and step.decision.spot_id != spot:
                        switches += 1
                        causes[_switch_cause(lot, obs, step.beliefs, spot, delta)] += 1
                    spot = step.decision.spot_id
                v = step.command[0]
                reversals += v * last < 0
                last = v if v != 0 else last
                world.step(*step.command)
                k += 1
            rows.append((seed, world.status, k, reversals, switches))
    finally:
        EgoPlanner._still_valid = original
    return rows, drops, causes


def _switch_cause(lot, obs, beliefs, spot: int, delta: float) -> str:
    if spot not in {int(s) for s in obs.vacant_spot_ids}:
        return "last spot not seen vacant"
    if beliefs is not None and beliefs[lot.spot_index(spot)] > delta:
        return "last spot believed taken (b > δ)"
    return "last spot still a candidate"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path)
    ap.add_argument("seeds")
    ap.add_argument("--sensing", choices=("run", "exact"), default="run", help="exact: the paper's sensor instead")
    ap.add_argument("--planner-param", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--tracker-param", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--method", default="bezier")
    ap.add_argument("--mode", choices=("reactive", "non-reactive"), default="reactive")
    args = ap.parse_args(argv)
    over = parse_planner_params(args.planner_param)
    tracker = parse_tracker_params(args.tracker_param)
    rows, drops, causes = run(args.out, seeds_of(args.seeds), args.sensing == "exact", over, args.method, tracker,
                              args.mode == "reactive")
    print("| seed | outcome | steps | reversals | spot switches |\n|--:|---|--:|--:|--:|")
    for seed, status, steps, rev, switches in rows:
        print(f"| {seed} | {status} | {steps} | {rev} | {switches} |")
    print(f"\nspot switches ({sum(causes.values())}): " + ", ".join(f"{k} {n}" for k, n in causes.most_common()))
    print(f"plans dropped ({sum(drops.values())}): " + ", ".join(f"{k} {n}" for k, n in drops.most_common()))
    return 0


if __name__ == "__main__":
    sys.exit(main())

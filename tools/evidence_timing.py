"""When did the ego learn that the agents react (issue #28)? For chosen busy-lot seeds of one method: the first step
an agent braked for the ego (the simulator's ground truth), the first step the planner had evidence of it
(``collision.reactive_evidence``), and how many evasive steps the ego made before that evidence.

    python tools/evidence_timing.py OUT.jsonl SEEDS [KEY=VALUE ...] [--method bezier] [--t-final 60]

SEEDS as tools/run_seeds.py (``2,8,9`` or ``0-49``); KEY=VALUE are avp_planner parameters. One JSON line per seed
is printed and appended to OUT.jsonl. The episode is the one ``avp experiment`` runs (same worker set-up, reactive
mode), stepped here so that the planner's evidence can be read after each step.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))


def main(argv: list[str]) -> int:
    from run_seeds import seeds_of

    from avp_experiment import runner
    from avp_experiment.ego import MethodEgo
    from avp_experiment.episodes import _WORKER, _init_worker
    from avp_experiment.run_config import RunConfig, run_profile
    from avp_sim.core.factory import make_world

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("seeds")
    ap.add_argument("params", nargs="*", metavar="KEY=VALUE")
    ap.add_argument("--method", default="bezier")
    ap.add_argument("--t-final", type=float, default=60.0)
    a = ap.parse_args(argv)
    lot_file = str(ROOT / "src/avp_world/avp_world/maps/dlp_lot.yaml")
    sim = runner._with_lot(runner.parse_sim_params(["scenario.family=busy"]), lot_file)
    cfg = RunConfig(t_final=a.t_final, sim_overrides=sim, planner_overrides=runner.parse_planner_params(a.params))
    _init_worker(cfg)
    profile = run_profile(a.method, cfg)
    for seed in seeds_of(a.seeds):
        world = make_world(_WORKER["lot"], _WORKER["sim"], seed, True)
        ego = MethodEgo(_WORKER["lot"], profile, deterministic=True, intent_weights=cfg.intent_weights,
                        intent_seed=cfg.intent_seed, message_precision=cfg.message_precision)
        first_brake = first_evidence = None
        evasive_before = 0
        while not world.done:
            out = ego.step(world.observe())
            if first_evidence is None and ego.planner._evidence.seen:
                first_evidence = out.step
            if first_evidence is None and out.decision.trace.get("mode") == "evasive":
                evasive_before += 1
            world.step(*out.command)
            if first_brake is None and ((world.braking & world.is_dynamic).any() or world.ped_braking.any()):
                first_brake = out.step
        line = {"method": a.method, "seed": seed, "status": world.status, "first_brake_step": first_brake,
                "first_evidence_step": first_evidence, "evasive_steps_before_evidence": evasive_before}
        print(json.dumps(line), flush=True)
        with open(a.out, "a") as f:
            f.write(json.dumps(line) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

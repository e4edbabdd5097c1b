"""When did the ego learn that the agents react? For chosen busy-lot seeds of one method: the first step
an agent braked for the ego (the simulator's ground truth), the first step the planner had evidence of it
(``collision.reactive_evidence``), and how many evasive steps the ego made before that evidence.

    python tools/evidence_timing.py OUT.jsonl SEEDS [KEY=VALUE ...] [--method bezier] [--t-final 60]

SEEDS as tools/run_seeds.py (``2,8,9`` or ``0-49``); KEY=VALUE are avp_planner parameters. One JSON line per seed
is printed and appended to OUT.jsonl. The episode is the one ``avp experiment`` runs (same worker set-up, reactive
mode), stepped here so that the planner's evidence can be read after each step.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))


def main(argv: list[str]) -> int:
    from probe_episodes import emit, episodes

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("seeds")
    ap.add_argument("params", nargs="*", metavar="KEY=VALUE")
    ap.add_argument("--method", default="bezier")
    ap.add_argument("--t-final", type=float, default=60.0)
    a = ap.parse_args(argv)
    for seed, world, ego in episodes(a.method, a.seeds, a.t_final, planner_params=a.params):
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
        emit(a.out, {"method": a.method, "seed": seed, "status": world.status, "first_brake_step": first_brake,
                     "first_evidence_step": first_evidence, "evasive_steps_before_evidence": evasive_before})
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

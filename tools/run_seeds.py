"""Run chosen seeds of one method in-process and append their records (docs/research/unfreezing.md's ablation arms).

    python tools/run_seeds.py OUT.jsonl METHOD SEEDS [KEY=VALUE ...] [--lot FILE] [--family busy] [--t-final 60]
        [--mode reactive] [--workers 2]

SEEDS: ``0-49``, ``1,4,8`` or ``0-49,150-199``. KEY=VALUE are avp_planner parameters (as ``avp experiment
--planner-param``); METHOD is a method name or a method profile's path. Each record is the one ``avp experiment``
writes (same runner, same worker set-up), less its per-step timings and ego poses; a line per episode is printed as
it ends. Unlike ``avp experiment`` it does not check that the seeds are valid scenarios, keep a run folder, resume
or summarise: it is for re-running the same few seeds under several settings.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def seeds_of(spec: str) -> list[int]:
    """``0-49``, ``1,4,8`` or a mix such as ``0-49,150-199,61``."""
    out: list[int] = []
    for part in spec.split(","):
        a, _, b = part.partition("-")
        out.extend(range(int(a), int(b or a) + 1))
    return out


def main(argv: list[str]) -> int:
    from avp_episode.run_config import RunConfig
    from avp_experiment import runner

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("method")
    ap.add_argument("seeds")
    ap.add_argument("params", nargs="*", metavar="KEY=VALUE")
    ap.add_argument("--lot", default=str(ROOT / "src/avp_world/avp_world/maps/dlp_lot.yaml"))
    ap.add_argument("--family", default="busy")
    ap.add_argument("--t-final", type=float, default=60.0)
    ap.add_argument("--mode", default="reactive", choices=("reactive", "non_reactive"))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--sim-param", action="append", default=[], metavar="KEY=VALUE",
                    help="an avp_sim parameter (repeatable), e.g. agents_yield=true")
    a = ap.parse_args(argv)
    sim = runner._with_lot(runner.parse_sim_params([f"scenario.family={a.family}", *a.sim_param]),
                           str(Path(a.lot).resolve()))
    cfg = RunConfig(t_final=a.t_final, sim_overrides=sim, planner_overrides=runner.parse_planner_params(a.params))
    keys = [(a.method, s, a.mode) for s in seeds_of(a.seeds)]
    ctx = mp.get_context("fork")
    with ctx.Pool(a.workers, initializer=runner._init_worker, initargs=(cfg, True)) as pool, open(a.out, "a") as f:
        for r in pool.imap_unordered(runner._worker_episode, keys):
            r.pop("step_timings", None), r.pop("ego_poses", None)
            f.write(json.dumps(r) + "\n")
            f.flush()
            print(r["seed"], r["status"], r["interrupted_steps"], r["decision_trace"]["steps_by_mode"], flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

"""What the failed episodes of a Table I run have in common.

For every failed record of ``OUT/episodes.jsonl`` the episode is run again in this process exactly as the runner
ran it (same seed, mode, method profile, intent weights and deterministic settings — the record is checked to come
out equal) while the ego's decisions are logged. Reported per failure: the dynamic vehicles of the scenario
(ParkSim maneuver ``side/stop/entry`` and target spot, :mod:`avp_scenario.scenario`), the spot the ego was heading
for at the end, whether that is a dynamic vehicle's target, and the closest approach (centre distance) between the
ego and each dynamic vehicle. Beside it, how often each maneuver occurs in all scenarios of the run, so that a
maneuver over-represented among the failures stands out.

Usage: ``python -m avp_experiment.failures OUT [--markdown FILE] [--workers N]`` (``OUT`` as given to
``avp experiment``; the run settings are read from ``OUT/run.json``).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from pathlib import Path

import numpy as np

from avp_episode.episodes import _WORKER, _init_worker, run_episode_inproc
from avp_episode.metrics import comparable
from avp_episode.run_config import RunConfig, run_profile
from avp_experiment.results import RUN_FILE, read_results, records_file


def _config(out: Path) -> RunConfig:
    run = json.loads((out / RUN_FILE).read_text())["config"]
    return RunConfig(t_final=run["t_final"], ade_horizon=run["ade_horizon"], intent_weights=run["intent_weights"],
                     intent_seed=run["intent_seed"], message_precision=run["message_precision"],
                     sim_overrides=run.get("sim_overrides", {}), protocol=run.get("protocol", "default"),
                     planner_overrides=run.get("planner_overrides", {}),
                     tracker_overrides=run.get("tracker_overrides", {}))


def replay_failure(lot, sim_p: dict, record: dict, cfg: RunConfig) -> dict:
    """Run the record's episode again as the runner does (:func:`~.episodes.run_episode_inproc`), watching the ego's
    decisions and its distance to the dynamic vehicles; returns what :func:`main` reports."""
    from avp_sim.core.factory import make_world

    dyn = [v for v in make_world(lot, sim_p, record["seed"], record["mode"] == "reactive").scenario.vehicles
           if not v.parked]
    closest = np.full(len(dyn), np.inf)
    targets: list[int] = []

    def watch(world, out) -> None:
        if out.decision.mode == "park":
            targets.append(int(out.decision.spot_id))
        if dyn:
            rows = [int(np.nonzero(world.vehicle_ids == v.id)[0][0]) for v in dyn]
            np.minimum(closest, np.hypot(*(world.states[rows, :2] - world.ego[:2]).T), out=closest)

    again = run_episode_inproc(lot, sim_p, run_profile(record["method"], cfg), record["seed"],
                               record["mode"] == "reactive", cfg, on_step=watch)
    last = targets[-1] if targets else -1
    return {"seed": record["seed"], "mode": record["mode"], "method": record["method"], "status": record["status"],
            "reproduced": comparable(again) == comparable(record), "ego_target": last,
            "ego_target_is_agents": bool(last >= 0 and any(v.target_spot_id == last for v in dyn)),
            "agents": [{"id": int(v.id), "maneuver": v.maneuver, "target": int(v.target_spot_id),
                        "closest_m": round(float(c), 2)} for v, c in zip(dyn, closest, strict=True)]}


def maneuver_counts(lot, sim_p: dict, seeds: list[int]) -> Counter:
    """How many dynamic vehicles of the run's scenarios do each maneuver (the setup does not depend on the mode)."""
    from avp_scenario.scenario import generate_paper_scenario
    from avp_sim.core.factory import scenario_params

    params = scenario_params(sim_p)
    c: Counter = Counter()
    for s in seeds:
        sc = generate_paper_scenario(lot, s, True, params)
        c.update(v.maneuver for v in sc.vehicles if not v.parked)
    return c


def markdown(rows: list[dict], counts: Counter, n_seeds: int) -> str:
    lines = ["| seed | mode | method | status | reproduced | ego heading for | an agent's target | agents "
             "(maneuver → target, closest approach) |", "|--:|---|---|---|---|--:|---|---|"]
    for r in rows:
        agents = "; ".join(f"{a['id']}: {a['maneuver']} → {a['target']}, {a['closest_m']:.1f} m" for a in r["agents"])
        again = "yes" if r["reproduced"] else "NO"
        lines.append(f"| {r['seed']} | {r['mode']} | {r['method']} | {r['status']} | {again}"
                     f" | {r['ego_target'] if r['ego_target'] >= 0 else '—'} | "
                     f"{'yes' if r['ego_target_is_agents'] else 'no'} | {agents} |")
    failed = Counter(a["maneuver"] for r in rows for a in r["agents"])
    total = sum(counts.values())
    lines += ["", f"Maneuvers of the dynamic vehicles: in the failed episodes vs in all {n_seeds} scenarios of the run",
              "", "| maneuver | in failed episodes | in all scenarios |", "|---|--:|--:|"]
    for m, n in sorted(counts.items(), key=lambda kv: -kv[1]):
        lines.append(f"| {m} | {failed.get(m, 0)} | {n} ({100 * n / total:.1f} %) |")
    return "\n".join(lines) + "\n"


def _replay(record: dict) -> dict:
    return replay_failure(_WORKER["lot"], _WORKER["sim"], record, _WORKER["cfg"])


def _counts(seeds: list[int]) -> Counter:
    return maneuver_counts(_WORKER["lot"], _WORKER["sim"], seeds)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m avp_experiment.failures", description=__doc__.split("\n")[0])
    ap.add_argument("out", help="the folder given to avp experiment --out")
    ap.add_argument("--markdown", help="also write the tables to this Markdown file")
    ap.add_argument("--workers", type=int, default=2, help="processes re-running episodes (0: this one)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    try:
        cfg = _config(out)
        records = read_results(records_file(out))
    except (OSError, KeyError, ValueError) as e:
        print(f"[failures] cannot read the run in {out}: {e}", file=sys.stderr)
        return 2
    failed = sorted((r for r in records if not r["success"]), key=lambda r: (r["seed"], r["mode"], r["method"]))
    seeds = sorted({int(r["seed"]) for r in records})
    if args.workers > 0 and failed:
        from avp_episode.pool import make_pool

        with make_pool(args.workers, _init_worker, (cfg, True)) as pool:
            rows = list(pool.map(_replay, failed))
            counts_parts = list(pool.map(_counts, [seeds[i::args.workers] for i in range(args.workers)]))
        counts: Counter = sum(counts_parts, Counter())
    else:  # the runner's worker state, in this process
        _init_worker(cfg)
        rows = [_replay(r) for r in failed]
        counts = _counts(seeds)
    for row in rows:
        print(json.dumps(row), flush=True)
    text = markdown(rows, counts, len(seeds))
    print(text)
    if args.markdown:
        Path(args.markdown).write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

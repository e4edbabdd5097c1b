#!/usr/bin/env python3
"""Benchmark of one decision step of the ego planner (paper §V-D: park / explore / idle with Hybrid A*).

``--capture`` drives seeded episodes of the paper lot (§VI-A; reactive and non-reactive) with the planner
itself (beliefs from observation only, no predictions) and stores every ``--every``-th decision-step
query (the observation, with the last two history states of each vehicle, and the planner-internal belief
map used at that step) in ``bench/data/planner_queries.json``. Two ego starts: the paper's (top of the
middle road, "paper") and, to include steps with many candidate spots and dynamic vehicles close by, the
middle of the contested stretch of the middle road (21.5, 22, -π/2; "mid"); identical queries are stored
once.

Without ``--capture`` the stored queries are replayed: each one is decided **from scratch** by a fresh
:class:`EgoPlanner` (no plan being executed, no caches; every candidate spot considered, with branch and
bound) with the stored beliefs and no predictions (observed dynamic agents get the planner's
constant-velocity fallback); a second pass turns branch and bound off, so that every candidate spot is
searched. Printed: median / p95 / max time per decision step, time per Hybrid A* spot query, how often a
plan is found among the queries for which one exists (existence decided by the same planner with generous
limits: 30 000 iterations and 5 s per search, 60 s per step), and peak memory (``ru_maxrss`` of the
process, and the tracemalloc peak of one decision step).

Usage:
    python bench/bench_planner.py --capture [--seeds 0-19] [--every 10]
    python bench/bench_planner.py [--limit N] [--no-reference] [--worst N]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import resource
import time
import tracemalloc
from dataclasses import replace
from pathlib import Path

import numpy as np

from avp_motion.settings import PlannerSettings
from avp_planner.core.decision import EgoPlanner
from avp_world.lot import load_bundled_lot
from avp_world.types import Observation, ObservedPedestrian, ObservedVehicle

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "bench" / "data" / "planner_queries.json"
STARTS = {"paper": None, "mid": (21.5, 22.0, -math.pi / 2)}


def _round(a, nd=6):
    return np.round(np.asarray(a, dtype=float), nd).tolist()


def obs_to_dict(obs: Observation) -> dict:
    return {
        "step": int(obs.step), "dt": obs.dt, "ego_pose": _round(obs.ego_pose), "ego_length": obs.ego_length,
        "ego_width": obs.ego_width, "ego_speed": round(float(obs.ego_speed), 6),
        "vacant": [int(i) for i in obs.vacant_spot_ids], "occupied": [int(i) for i in obs.occupied_spot_ids],
        "vehicles": [{"id": v.id, "length": v.length, "width": v.width, "static": bool(v.is_static),
                      "history": _round(v.history[-2:])} for v in obs.vehicles],
        "pedestrians": [{"id": p.id, "radius": p.radius, "position": _round(p.position),
                         "previous": _round(p.previous_position)} for p in obs.pedestrians],
    }


def obs_from_dict(d: dict) -> Observation:
    return Observation(
        step=d["step"], dt=d["dt"], ego_pose=np.array(d["ego_pose"]), ego_length=d["ego_length"],
        ego_width=d["ego_width"], ego_speed=d["ego_speed"], vacant_spot_ids=np.array(d["vacant"], dtype=np.int64),
        occupied_spot_ids=np.array(d["occupied"], dtype=np.int64),
        vehicles=tuple(ObservedVehicle(v["id"], v["length"], v["width"], v["static"], np.array(v["history"]))
                       for v in d["vehicles"]),
        pedestrians=tuple(ObservedPedestrian(p["id"], p["radius"], np.array(p["position"]), np.array(p["previous"]))
                          for p in d["pedestrians"]),
    )


def _seeds(text: str) -> list[int]:
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(s) for s in text.split(",")]


def capture(args) -> None:
    import avp_sim.params
    from avp_common.params import load_yaml_params
    from avp_scenario.scenario import ScenarioError, generate_paper_scenario
    from avp_sim.core.factory import make_world, scenario_params, world_config
    from avp_sim.core.world import World

    p = load_yaml_params(ROOT / "src/avp_sim/config/sim.param.yaml", "avp_sim", avp_sim.params.SIM_PARAMS)
    lot = load_bundled_lot("paper_lot")
    queries, episodes, seen = [], [], set()
    n_dup = 0
    for start, reactive, seed in [(s, r, k) for s in args.starts.split(",") for r in (True, False)
                                  for k in _seeds(args.seeds)]:
        if start == "paper":
            world = make_world(lot, p, seed, reactive)
        else:
            try:
                sc = generate_paper_scenario(lot, seed, reactive,
                                             replace(scenario_params(p), ego_start=STARTS[start]))
            except ScenarioError:
                continue
            world = World(lot, sc, world_config(p))
        planner = EgoPlanner(lot, PlannerSettings())
        while not world.done:
            obs = world.observe()
            beliefs = planner.update_beliefs(obs).copy()  # what decide(obs, None) works with
            d = planner.decide(obs, None, [])
            if obs.step % args.every == 0 or d.replanned:
                q = {"start": start, "seed": seed, "reactive": reactive, "obs": obs_to_dict(obs),
                     "beliefs": _round(beliefs, 3), "closed_loop_mode": d.mode}
                key = json.dumps([q["obs"] | {"step": 0}, q["beliefs"]], sort_keys=True)
                if key in seen:  # e.g. a reactive episode in which no agent ever had to brake
                    n_dup += 1
                else:
                    seen.add(key)
                    queries.append(q)
            world.step(*d.command)
        m = world.metrics
        episodes.append({"start": start, "seed": seed, "reactive": reactive, "status": world.status,
                         "spot": m.parked_spot_id, "parking_time": m.parking_time, "steps": m.steps})
        print(f"{start:5s} seed {seed:2d} {'reactive' if reactive else 'non-reactive':12s} {world.status:9s} "
              f"{m.collision_with:12s} spot {m.parked_spot_id:3d} t_park {m.parking_time:5.1f} s; "
              f"{len(queries)} queries so far")
    DATA.parent.mkdir(parents=True, exist_ok=True)
    DATA.write_text(json.dumps({"lot": lot.name, "every": args.every, "episodes": episodes, "queries": queries},
                               separators=(",", ":")))
    print(f"wrote {len(queries)} queries to {DATA.relative_to(ROOT)} ({DATA.stat().st_size / 1e6:.2f} MB); "
          f"{n_dup} duplicates (identical observation and beliefs) left out")


def _decide(lot, settings, q) -> tuple[float, object]:
    planner = EgoPlanner(lot, settings)
    obs = obs_from_dict(q["obs"])
    t0 = time.perf_counter()
    d = planner.decide(obs, np.array(q["beliefs"]), [])
    return time.perf_counter() - t0, d


def replay(args) -> None:
    data = json.loads(DATA.read_text())
    lot = load_bundled_lot(data["lot"])
    queries = data["queries"][: args.limit] if args.limit else data["queries"]
    settings = PlannerSettings()
    EgoPlanner(lot, settings)  # warm-up: builds the Reeds-Shepp look-up table once per process
    for q in queries[:5]:
        _decide(lot, settings, q)
    times, spot_q, modes, details = [], [], [], []
    for q in queries:
        t, d = _decide(lot, settings, q)
        times.append(t)
        modes.append(d.mode)
        spot_q += [e["time_s"] for e in d.stats.get("queries", []) if e["mode"] == "park"]
        details.append((t, q, d))
    ms = np.array(times) * 1e3
    sq = np.array(spot_q) * 1e3
    n_ep = len({(q.get("start"), q["seed"], q["reactive"]) for q in queries})
    print(f"queries: {len(queries)} decision steps from {n_ep} "
          f"episodes ({data['lot']}); modes: park {modes.count('park')}, explore {modes.count('explore')}, "
          f"idle {modes.count('idle')}")
    print(f"time per decision step: median {np.median(ms):.1f} ms, p95 {np.percentile(ms, 95):.1f} ms, "
          f"mean {ms.mean():.1f} ms, max {ms.max():.1f} ms")
    for start in sorted({q.get("start", "paper") for q in queries}):
        sel = np.array([q.get("start", "paper") == start for q in queries])
        ncand = np.mean([len(q["obs"]["vacant"]) for q, m in zip(queries, sel, strict=True) if m])
        print(f"  start '{start}': {sel.sum()} steps (mean {ncand:.1f} observed vacant spots), median "
              f"{np.median(ms[sel]):.1f} ms, p95 {np.percentile(ms[sel], 95):.1f} ms")
    if len(sq):
        print(f"time per Hybrid A* spot query: median {np.median(sq):.2f} ms, p95 {np.percentile(sq, 95):.2f} ms "
              f"({len(sq)} queries, {len(sq) / len(queries):.2f} per decision step)")
    for t, q, d in sorted(details, key=lambda e: -e[0])[: args.worst]:
        qs = ", ".join(f"{e['mode'][0]}{e['target']}:{'ok' if e['success'] else e['reason']}"
                       f"/{e['iterations']}it/{1e3 * e['time_s']:.0f}ms" for e in d.stats.get("queries", []))
        print(f"  slow: {1e3 * t:.0f} ms {q.get('start', 'paper')} seed {q['seed']} step {q['obs']['step']} "
              f"ego {q['obs']['ego_pose']} -> "
              f"{d.mode} {d.spot_id} ({d.n_candidates} candidates) [{qs}]")
    exhaustive = replace(settings, decision=replace(settings.decision, branch_and_bound=False))
    ex_times, ex_q = [], []
    for q in queries:
        t, d = _decide(lot, exhaustive, q)
        ex_times.append(t)
        ex_q += [e["time_s"] for e in d.stats.get("queries", []) if e["mode"] == "park"]
    ex = np.array(ex_times) * 1e3
    print(f"without branch and bound (every candidate spot searched, {len(ex_q) / len(queries):.2f} spot queries "
          f"per step): median {np.median(ex):.1f} ms, p95 {np.percentile(ex, 95):.1f} ms, max {ex.max():.1f} ms "
          f"per decision step; spot query median {1e3 * np.median(ex_q):.2f} ms, "
          f"p95 {1e3 * np.percentile(ex_q, 95):.2f} ms")
    if not args.no_reference:
        big = replace(settings, search=replace(settings.search, max_iterations=30000, time_cap=5.0),
                      decision=replace(settings.decision, decision_time_cap=60.0))
        has_park = has_any = got_park = got_any = 0
        for q, mode in zip(queries, modes, strict=True):
            _, ref = _decide(lot, big, q)
            if ref.mode == "park":
                has_park += 1
                got_park += mode == "park"
            if ref.mode != "idle":
                has_any += 1
                got_any += mode != "idle"
        print(f"parking plan found in {got_park}/{has_park} decision steps that have one "
              f"({100.0 * got_park / max(has_park, 1):.1f} %); any plan (park or explore) in {got_any}/{has_any} "
              f"({100.0 * got_any / max(has_any, 1):.1f} %)")
    tracemalloc.start()
    peak = 0
    for q in queries[: min(len(queries), 40)]:
        tracemalloc.reset_peak()
        _decide(lot, settings, q)
        peak = max(peak, tracemalloc.get_traced_memory()[1])
    tracemalloc.stop()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"peak memory: {peak / 1e6:.1f} MB traced per decision step (tracemalloc), process max RSS {rss:.0f} MB")
    print(f"machine: {platform.platform()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, "
          f"numpy {np.__version__}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--capture", action="store_true", help="run episodes and store the queries")
    ap.add_argument("--seeds", default="0-19", help="capture: seeds, e.g. 0-19 or 1,4,7 (default 0-19)")
    ap.add_argument("--every", type=int, default=10, help="capture: every N-th step (and every replanning step)")
    ap.add_argument("--starts", default="paper,mid", help="capture: ego starts, of " + ", ".join(STARTS))
    ap.add_argument("--limit", type=int, default=0, help="replay: only the first N queries")
    ap.add_argument("--no-reference", action="store_true", help="replay: skip the generous-limits reference run")
    ap.add_argument("--worst", type=int, default=0, help="replay: list the N slowest decision steps")
    args = ap.parse_args()
    capture(args) if args.capture else replay(args)


if __name__ == "__main__":
    main()

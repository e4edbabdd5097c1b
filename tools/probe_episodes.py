"""Shared by the probe tools (evidence_timing.py, agent_overlaps.py, stolen_spots.py): step one method's episodes
by hand, in the configuration of the busy lot's records.

:func:`episodes` yields, per seed, the simulator and the method's in-process ego exactly as ``avp experiment`` sets
them up (same worker set-up, reactive mode), for a tool to step and watch; :func:`emit` prints a result line and
appends it to the tool's output file.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
DLP_LOT = ROOT / "src/avp_world/avp_world/maps/dlp_lot.yaml"


def run_config(t_final: float, planner_params: list[str] = (), sim_params: list[str] = (), lot: str = "busy"):
    """The run configuration of the busy DLP lot's records (``lot`` "busy", as tools/run_seeds.py makes it) or of
    the paper's lot ("paper"), with avp_sim / avp_planner KEY=VALUE overrides."""
    from avp_episode.run_config import RunConfig
    from avp_experiment import runner

    if lot == "busy":
        sim = runner._with_lot(runner.parse_sim_params(["scenario.family=busy", *sim_params]), str(DLP_LOT))
    else:
        sim = runner.parse_sim_params(list(sim_params))
    return RunConfig(t_final=t_final, sim_overrides=sim, planner_overrides=runner.parse_planner_params(planner_params))


def episodes(method: str, seeds: str, t_final: float, sim_params: list[str] = (), planner_params: list[str] = (),
             lot: str = "busy") -> Iterator[tuple[int, object, object]]:
    """(seed, World, MethodEgo) for each seed of ``seeds`` (``0-49`` or ``2,8,9``) with :func:`run_config`."""
    from run_seeds import seeds_of

    from avp_episode.ego import MethodEgo
    from avp_episode.episodes import _WORKER, _init_worker
    from avp_episode.run_config import run_profile
    from avp_sim.core.factory import make_world

    cfg = run_config(t_final, planner_params, sim_params, lot)
    _init_worker(cfg)
    profile = run_profile(method, cfg)
    for seed in seeds_of(seeds):
        world = make_world(_WORKER["lot"], _WORKER["sim"], seed, True)
        ego = MethodEgo(_WORKER["lot"], profile, deterministic=True, intent_weights=cfg.intent_weights,
                        intent_seed=cfg.intent_seed, message_precision=cfg.message_precision)
        yield seed, world, ego


def emit(out: str, line: dict) -> None:
    """Print ``line`` as JSON and append it to ``out``."""
    print(json.dumps(line), flush=True)
    with open(out, "a") as f:
        f.write(json.dumps(line) + "\n")

"""Generated scenarios kept on disk: the busy lot's generator plans every arrival's and departure's maneuver, about
9 s of CPU a seed, and a suite runs each seed once per row (docs/experiment.md, "The headline table").

A scenario is stored as ``<dir>/scenario-<digest>.npz`` in the stack's cache directory
(:mod:`avp_world.disk_cache`; ``AVP_CACHE_DIR=""`` turns it off) without pickling: its arrays as they are and its
numbers in a JSON text, which gives every float back bit for bit. The digest covers the generator's key (seed,
reactive, the family's parameters), the lot's geometry, numpy's version and the source of every module of
``avp_sim.core`` and ``avp_world``, so a change to any of them generates anew. The seed alone picks the scenario;
nothing of the method that will drive in it enters the key. A file that does not read back whole is generated
again and replaced.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

import numpy as np

from avp_scenario.scenario import PedestrianAgent, Scenario, VehicleAgent
from avp_world.disk_cache import cached
from avp_world.lot import LotMap
from avp_world.vehicle import VehicleSpec

FORMAT = 1  # bump when the file layout changes


def lot_key(lot: LotMap) -> str:
    """SHA-256 of the lot's geometry and scenario block (floats by repr: exact)."""
    text = repr((lot.name, lot.boundary.tobytes(), lot.entrance.tobytes(), lot.spots, lot.roads,
                 sorted(lot.scenario.items(), key=lambda kv: str(kv[0]))))
    return hashlib.sha256(text.encode()).hexdigest()


def _sources() -> list[Path]:
    """Every source file of avp_sim.core, avp_scenario, avp_traffic and avp_world: the generator's code and all it
    may import."""
    import avp_scenario
    import avp_traffic
    import avp_world

    here = Path(__file__).resolve().parent
    return sorted(here.glob("*.py")) + [f for m in (avp_scenario, avp_traffic, avp_world)
                                        for f in sorted(Path(m.__file__).resolve().parent.glob("*.py"))]


def _pack(sc: Scenario) -> dict[str, np.ndarray]:
    v, p = sc.vehicles, sc.pedestrians
    meta = {"seed": sc.seed, "reactive": sc.reactive, "ego": asdict(sc.ego), "dt": sc.dt, "t_hist": sc.t_hist,
            "passiveness_step": sc.passiveness_step,
            "vehicles": [[a.id, a.length, a.width, a.passiveness, a.target_spot_id, a.maneuver, a.parked] for a in v],
            "pedestrians": [[q.id, q.radius, q.passiveness] for q in p]}
    return {
        "meta": np.array(json.dumps(meta)),
        "ego_start": np.asarray(sc.ego_start, dtype=float),
        "veh_state": np.array([a.initial_state for a in v], dtype=float).reshape(len(v), 3),
        "veh_steps": np.array([len(a.controls) for a in v], dtype=np.int64),
        "veh_controls": np.concatenate([np.asarray(a.controls, float).reshape(-1, 2) for a in v] + [np.zeros((0, 2))]),
        "ped_position": np.array([q.initial_position for q in p], dtype=float).reshape(len(p), 2),
        "ped_steps": np.array([len(q.controls) for q in p], dtype=np.int64),
        "ped_controls": np.concatenate([np.asarray(q.controls, float).reshape(-1, 2) for q in p] + [np.zeros((0, 2))]),
    }


def _split(controls: np.ndarray, steps: np.ndarray) -> list[np.ndarray]:
    if int(steps.sum()) != len(controls) or (steps < 0).any():
        raise ValueError("control counts do not add up")
    return np.split(controls, np.cumsum(steps)[:-1]) if len(steps) else []


def _unpack(z) -> Scenario:
    meta = json.loads(str(z["meta"]))
    vehicles = tuple(
        VehicleAgent(id=m[0], length=m[1], width=m[2], initial_state=s, controls=c, passiveness=m[3],
                     target_spot_id=m[4], maneuver=m[5], parked=m[6])
        for m, s, c in zip(meta["vehicles"], z["veh_state"], _split(z["veh_controls"], z["veh_steps"]), strict=True))
    pedestrians = tuple(
        PedestrianAgent(id=m[0], radius=m[1], initial_position=s, controls=c, passiveness=m[2])
        for m, s, c in zip(meta["pedestrians"], z["ped_position"], _split(z["ped_controls"], z["ped_steps"]),
                           strict=True))
    return Scenario(seed=meta["seed"], reactive=meta["reactive"], ego_start=z["ego_start"],
                    ego=VehicleSpec(**meta["ego"]), vehicles=vehicles, pedestrians=pedestrians, dt=meta["dt"],
                    t_hist=meta["t_hist"], passiveness_step=meta["passiveness_step"])


def _read(path: Path) -> Scenario:
    with np.load(path, allow_pickle=False) as z:
        return _unpack(z)


def cached_scenario(lot: LotMap, key: tuple, generate: Callable[[], Scenario]) -> Scenario:
    """The scenario ``generate()`` makes for ``key`` (every input of the generator but the lot), read from the cache
    when a whole one is there, else generated and stored (only generated scenarios: a scenario file's further egos
    are not kept)."""
    return cached("scenario", ".npz", (FORMAT, key, lot_key(lot)), _sources(), _read, generate,
                  lambda f, sc: np.savez_compressed(f, **_pack(sc)), keep=lambda sc: not sc.ego_entries)


__all__ = ["cached_scenario", "lot_key"]

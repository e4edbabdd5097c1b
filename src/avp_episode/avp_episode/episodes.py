"""One episode in process (paper §VI-B): the simulator core and one method's ego, and the worker processes that run
them for :mod:`.runner` (a local pool) and :mod:`.ray_backend` (Ray tasks). A worker is set up once
(:func:`_init_worker`: the run's configuration, the lot, the method profiles it has loaded), then runs keys
``(method, seed, mode)`` (:func:`_worker_episode`)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from avp_episode.profiles import MethodProfile
from avp_episode.run_config import ORACLE_HORIZON, Key, RunConfig, run_profile, sim_values, tracker_values


def run_episode_inproc(lot, sim_p: dict, profile: MethodProfile, seed: int, reactive: bool, cfg: RunConfig,
                       on_step: Callable | None = None) -> dict:
    """One episode on the simulator core with the method's :class:`~.ego.MethodEgo`; returns its record.

    ``on_step(world, ego_step)``, if given, is called after every step (the failure analysis watches episodes)."""
    from avp_episode.ego import MethodEgo
    from avp_episode.metrics import episode_record, lot_record, prediction_errors
    from avp_episode.oracle import OracleEgo, ground_truth, seen_through
    from avp_sim.core.factory import make_world

    t0 = time.perf_counter()
    world = make_world(lot, sim_p, seed, reactive)
    from avp_episode.sensing import relabel_predictions, sensed_observer, truth_ids

    noisy = sensed_observer(world, sim_p, seed, tracker_values(cfg))  # None for exact sensing: world.observe
    observe = noisy or world.observe
    ego = (OracleEgo if profile.ground_truth else MethodEgo)(
        lot, profile, deterministic=True, intent_weights=cfg.intent_weights, intent_seed=cfg.intent_seed,
        message_precision=cfg.message_precision)
    from avp_motion.trace import DecisionTrace

    preds: dict[int, list] = {}
    timings: list[dict] = []
    trace = DecisionTrace(world.dt)
    while not world.done:
        obs = observe()
        if profile.ground_truth:  # the oracle bound, and only it, is told the simulator's state (.oracle)
            truth = ground_truth(world, ORACLE_HORIZON)
            ego.tell(truth if noisy is None else seen_through(truth, world, obs))
        out = ego.step(obs)
        preds[out.step] = [p for p in out.predictions if not p.is_pedestrian]
        if noisy is not None:  # tracks: scored against the vehicle each follows (truth for scoring only)
            preds[out.step] = relabel_predictions(preds[out.step], truth_ids(world, obs))
        timings.append(out.timings)
        if out.decision is not None:
            trace.add(out.step, out.decision)
        world.step(*out.command)
        if on_step is not None:
            on_step(world, out)
    ade, fde = prediction_errors(preds, world.log_vehicles, world.vehicle_ids, world.dt, cfg.ade_horizon)
    return episode_record(method=profile.name, seed=seed, reactive=reactive, status=world.status,
                          metrics=world.metrics.as_dict(), min_ade=ade, min_fde=fde, step_timings=timings,
                          horizon=cfg.ade_horizon, transport="inproc", wall_s=time.perf_counter() - t0,
                          lot=lot_record(lot), ego_poses=np.asarray(world.log_ego), decision_trace=trace.summary())


_WORKER: dict[str, Any] = {}


def _init_worker(cfg: RunConfig, pool_worker: bool = False, sources: dict[str, str] | None = None) -> None:
    import torch

    if pool_worker:
        from avp_episode.pool import worker_signals

        worker_signals()

    torch.set_num_threads(1)
    from avp_sim.core.factory import load_lot_param

    sim = sim_values(cfg)
    # sources: profile name -> its file, so a profile given by path (a plugin's) loads in a worker too
    _WORKER.update(cfg=cfg, lot=load_lot_param(sim["lot_file"]), sim=sim, profiles={}, sources=sources or {})


def _worker_episode(key: Key) -> dict | list[dict]:
    """One episode's record; a fleet's (a key named ``fleet:M1,M2,...``, :mod:`.fleet`): a record per ego."""
    from avp_episode.fleet import fleet_names

    method, seed, mode = key
    profiles = _WORKER["profiles"]
    names = fleet_names(method) or [method]
    for name in names:
        if name not in profiles:
            profiles[name] = run_profile(_WORKER["sources"].get(name, name), _WORKER["cfg"])
    if len(names) > 1 or method != names[0]:
        from avp_episode.fleet import run_fleet_inproc

        return run_fleet_inproc(_WORKER["lot"], _WORKER["sim"], [profiles[n] for n in names], seed,
                                mode == "reactive", _WORKER["cfg"])
    return run_episode_inproc(_WORKER["lot"], _WORKER["sim"], profiles[method], seed, mode == "reactive",
                              _WORKER["cfg"])


def episode_in_worker(key: Key, cfg: RunConfig, sources: dict[str, str]) -> dict:
    """One episode in a long-lived worker process of another backend (a Ray task): the worker is set up as
    :func:`~.runner.run_inproc`'s are, once per (cfg, sources), then runs ``key``."""
    ident = (cfg, sorted(sources.items()))
    if _WORKER.get("ident") != ident:
        _WORKER.clear()
        _init_worker(cfg, sources=sources)
        _WORKER["ident"] = ident
    return _worker_episode(key)

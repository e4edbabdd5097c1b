"""``avp experiment``: the Table I runner (paper §VI-B, docs/experiment.md).

Episodes are (method, seed, mode) triples: the first ``scenarios`` seeds >= ``seed_base`` that the §VI-A
scenario generator can build (:func:`valid_seeds`; a seed's reactive and non-reactive runs share the same
setup), reactive and/or non-reactive agents, and the chosen method profiles. Each finished episode is appended to
``OUT/episodes.jsonl`` as one JSON line (:func:`~.metrics.episode_record`) and flushed, so a run can be
interrupted and the same command continues where it stopped (episodes already in the file are skipped; a
line cut off by the interruption is dropped). ``OUT/run.json`` records what the results depend on (t_f, the
minADE horizon, the intent weights, the method profiles); re-running into the same folder with different
values is refused. Each invocation appends a line to ``OUT/runs.jsonl`` (start, wall time, episodes run, workers,
commit, options, load average) so that the wall time of a run split over several invocations can be stated. At
the end ``OUT/summary.md``, ``OUT/summary.json`` and ``OUT/plots/*.png`` are written
(:mod:`.summary`). The results folder itself (run.json, episodes.jsonl, runs.jsonl) is :mod:`.results`.

Transports: ``inproc`` runs each episode in a worker process (``concurrent.futures``, spawn, one torch
thread per worker; :mod:`.episodes`) on the simulator core and :class:`~.ego.MethodEgo`; ``ros`` runs them
through the live DDS graph (``avp_experiment_ros.transport``, a plugin of :mod:`.transports`; one episode at a
time). The planner's wall-clock caps are lifted in both (:data:`~.profiles.DETERMINISTIC_PLANNER`), so the same
command gives the same episodes.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from avp_episode.episodes import (  # noqa: F401 - re-exported: the runner's API
    _WORKER,
    ORACLE_HORIZON,
    _init_worker,
    _worker_episode,
    episode_in_worker,
    run_episode_inproc,
)
from avp_episode.pool import end_workers_on_sigterm
from avp_episode.profiles import (
    MethodProfile,
    ProfileError,
    available_names,
)
from avp_episode.run_config import (  # noqa: F401 - re-exported: the runner's API
    DEFAULT_HORIZON,
    Key,
    RunConfig,
    run_profile,
    sim_values,
)
from avp_experiment.arguments import MODES, add_arguments  # noqa: E402 F401 - re-exported: the runner's API
from avp_experiment.results import (  # noqa: F401 - re-exported: the runner's API
    RESULTS_FILE,
    RUN_FILE,
    RUNS_LOG,
    SEEDS_FILE,
    ResultsWriter,
    check_method,
    check_run_file,
    code_commit,
    intent_identity,
    lock_folder,
    log_invocation,
    mode_name,
    profile_digest,
    read_results,
    record_key,
    records_file,
    run_identity,
)
from avp_experiment.seeds import valid_seeds  # noqa: F401 - re-exported: the runner's API

# ------------------------------------------------------------------------------------------ episodes


def run_inproc(keys: list[Key], cfg: RunConfig, workers: int, on_record: Callable[[dict], None],
               sources: dict[str, str] | None = None, pool: ProcessPoolExecutor | None = None) -> list[str]:
    """Run ``keys`` in ``workers`` processes (0: in this process), calling ``on_record`` as each finishes; ``pool``:
    a pool shared with other runs (:func:`.pool.shared_pool`) instead of one of this run's own.

    An episode that raises is reported on stderr (method, seed, mode and the error, one line) and left out of
    the results, so the same command retries it; the others go on. Returns those error lines.
    """
    from avp_episode.pool import collect, make_pool

    errors: list[str] = []

    def failed(key: Key, exc: BaseException) -> None:
        line = f"episode {key[0]} seed {key[1]} {key[2]} raised {type(exc).__name__}: {exc}"
        errors.append(line)
        print(f"[avp experiment] {line}", file=sys.stderr, flush=True)

    if pool is not None:
        collect({pool.submit(episode_in_worker, k, cfg, sources or {}): k for k in keys}, on_record, failed)
        return errors
    if workers <= 0:
        _init_worker(cfg, sources=sources)
        for k in keys:
            try:
                r = _worker_episode(k)
            except Exception as exc:  # noqa: BLE001 - one episode's bug must not stop the sweep
                failed(k, exc)
                continue
            on_record(r)
        return errors
    with make_pool(workers, _init_worker, (cfg, True, sources)) as own:
        try:
            collect({own.submit(_worker_episode, k): k for k in keys}, on_record, failed)
        except BaseException:
            own.shutdown(wait=False, cancel_futures=True)  # never wait for the whole queue to run unrecorded
            raise
    return errors


# ------------------------------------------------------------------------------------------ command


def episode_keys(methods: list[str], seeds: list[int], modes: tuple[bool, ...]) -> list[Key]:
    """Seed-major order, so that an interrupted run covers every method and mode for its first seeds."""
    return [(m, s, mode_name(r)) for s in seeds for r in modes for m in methods]


def resolve_methods(spec: str, cfg: RunConfig = RunConfig(), transport: str = "inproc", egos: int = 1
                    ) -> tuple[list[MethodProfile], dict[str, str]]:
    """(runnable profiles, {name: why skipped}) for 'all' or a comma-separated list of names / files. A profile that
    coordinates egos (``coordination``) runs only with several egos."""
    names = available_names() if spec == "all" else [s.strip() for s in spec.split(",") if s.strip()]
    run, skipped = [], {}
    for n in names:
        prof = run_profile(n, cfg)
        why = check_method(prof)
        if not why and prof.ground_truth and transport != "inproc":
            why = "an oracle bound: ground truth reaches the ego in-process only (--transport inproc)"
        if not why and prof.coordination != "none" and egos == 1:
            why = f"coordinates several egos (coordination: {prof.coordination}): run it with --egos K (K >= 2)"
        if why:
            skipped[prof.name] = why
        else:
            run.append(prof)
    return run, skipped


def run_experiment(args: argparse.Namespace) -> dict:
    """The ``avp experiment`` command (see :func:`add_arguments`); returns a small report."""
    if args.scenarios < 1:
        raise ValueError(f"--scenarios must be >= 1, got {args.scenarios}")
    if getattr(args, "backend", "local") == "ray":
        if args.transport != "inproc":
            raise ValueError("--backend ray runs in-process episodes: it takes --transport inproc")
        from avp_experiment.ray_backend import import_ray

        import_ray()  # one line saying how to install it, before anything is written
    elif getattr(args, "address", None):
        raise ValueError("--address is for --backend ray")
    if getattr(args, "suite", None):
        from avp_experiment.headline import run_suite

        if getattr(args, "sweep", None) or getattr(args, "ablation", False):
            raise ValueError("--suite runs its own grid: no --sweep or --ablation with it")
        from avp_episode.pool import shared_pool

        local = getattr(args, "backend", "local") == "local" and args.transport == "inproc"
        with shared_pool(args.workers if local else 0) as pool:  # one pool for every cell (.pool)
            args.shared_pool = pool
            return run_suite(args, run_experiment, _cell_args, resolve_methods)
    if getattr(args, "quick", False) or getattr(args, "columns", "") or getattr(args, "rows", ""):
        raise ValueError("--quick, --columns and --rows are for --suite")
    if getattr(args, "sweep", None) or getattr(args, "ablation", False):
        from avp_experiment.sweep import run_ablation, run_sweep

        if args.sweep and args.ablation:
            raise ValueError("--sweep and --ablation: one at a time")
        return (run_sweep if args.sweep else run_ablation)(args, run_experiment)
    out = Path(args.out)
    cfg = RunConfig(t_final=args.t_final, ade_horizon=args.ade_horizon, intent_weights=args.intent_weights,
                    intent_seed=args.intent_seed, message_precision=not args.float64_messages,
                    sim_overrides=_with_lot(parse_sim_params(args.sim_param), args.lot), protocol=args.protocol,
                    planner_overrides=parse_planner_params(args.planner_param),
                    tracker_overrides=parse_tracker_params(getattr(args, "tracker_param", None)))
    sensing = sim_values(cfg)["sensing.model"]
    if sensing != "exact" and args.transport != "inproc":  # the graph runs it (avp demo --sensing), not scored here
        raise ValueError(f"sensing.model {sensing}: --transport inproc only; over DDS the tracker's ids are not the "
                         "simulator's, which scoring the predictions needs (run the graph with `avp demo --sensing "
                         f"{sensing}`)")
    if cfg.tracker_overrides and sensing == "exact":
        raise ValueError("--tracker-param: the tracker runs with noisy sensing only; add --sim-param "
                         "sensing.model=realistic (or harsh)")
    from avp_episode.fleet import fleet_names, parse_fleet, run_units

    egos, fleet = getattr(args, "egos", 1), getattr(args, "fleet", "")
    if (egos != 1 or fleet) and args.transport not in ("inproc", "ros"):
        raise ValueError(f"--egos/--fleet: fleets run over --transport inproc or ros, not {args.transport!r}")
    spec = ",".join(dict.fromkeys(parse_fleet(fleet))) if fleet else args.methods
    n_egos = len(parse_fleet(fleet, egos if egos > 1 else None)) if fleet else egos
    profiles, skipped = resolve_methods(spec, cfg, args.transport, n_egos)
    for name, why in skipped.items():
        print(f"[avp experiment] skipping method {name!r}: {why}", file=sys.stderr)
    if not profiles:
        raise ValueError(f"no runnable method in --methods {args.methods!r}")
    units = run_units([p.name for p in profiles], egos, fleet)
    missing = sorted({n for u in units for n in fleet_names(u)} - {p.name for p in profiles})
    if missing:
        raise ValueError(f"--fleet: method(s) {missing} cannot run")
    ident = run_identity(cfg, profiles)
    if cfg.intent_weights:  # one clear error here rather than one per episode in the workers
        from avp_belief_map.bev import BEVConfig
        from avp_perception.core.pipeline import make_intent_predictor
        from avp_world.lot import load_bundled_lot

        make_intent_predictor(load_bundled_lot(), BEVConfig(), cfg.intent_weights, cfg.intent_seed)
    lock = lock_folder(out)
    try:
        return _run_locked(args, out, cfg, profiles, skipped, ident, units)
    finally:
        lock.close()


def _run_locked(args: argparse.Namespace, out: Path, cfg: RunConfig, profiles: list[MethodProfile],
                skipped: dict[str, str], ident: dict, units: list[str]) -> dict:
    """The part of :func:`run_experiment` that writes the results folder (which it holds locked). ``units``: what
    the keys name — the methods, or fleets of them (:mod:`.fleet`, a record per ego)."""
    from collections import Counter

    from avp_episode.fleet import fleet_names, fleet_table
    from avp_report.summary import write_summary

    check_run_file(out, ident)
    path = out / RESULTS_FILE
    records = dedupe_egos(read_results(records_file(out)))
    count = Counter(record_key(r) for r in records)
    done = {k for k, c in count.items() if c >= max(1, len(fleet_names(k[0])))}  # a fleet: every ego's record
    local = args.transport == "inproc" and getattr(args, "backend", "local") == "local"
    seeds, bad_seeds = valid_seeds(args.scenarios, args.seed_base, sim_values(cfg), out / SEEDS_FILE,
                                   getattr(args, "shared_pool", None), args.workers if local else 1)
    keys = episode_keys(units, seeds, MODES[args.mode])
    todo = [k for k in keys if k not in done]
    own = "".join(f"; {p.name}: {p.intent_weights} (its profile)" for p in profiles if p.intent_weights)
    print(f"[avp experiment] {len(keys)} episodes ({len(profiles)} methods x {args.scenarios} scenarios x "
          f"{len(MODES[args.mode])} modes; seeds {seeds[0]}..{seeds[-1]}"
          f"{', without ' + str(bad_seeds) + ' (no scenario)' if bad_seeds else ''}), {len(keys) - len(todo)} "
          f"already in {path}, {len(todo)} to run over --transport {args.transport}; intent CNN: {ident['intent']}"
          f"{own}", flush=True)
    n_run = 0
    errors: list[str] = []
    started, t0, commit = time.strftime("%Y-%m-%dT%H:%M:%S%z"), time.perf_counter(), code_commit()
    if todo and not args.summary_only and records_file(out) != path:
        raise ValueError(f"{records_file(out)}: the records of this folder are compressed; the runner appends to "
                         f"{path}: run `gunzip {records_file(out)}` first, then the same command")
    if todo and not args.summary_only:
        from tqdm import tqdm

        writer = ResultsWriter(path)
        bar = tqdm(total=len(todo), unit="ep", desc="episodes", disable=args.no_progress, smoothing=0.05)

        def on_record(got: dict | list[dict]) -> None:
            nonlocal n_run
            for r in got if isinstance(got, list) else [got]:  # a fleet's episode: a record per ego
                writer.write(r)
                records.append(r)
            n_run += 1
            bar.set_postfix_str(f"{r['method']} seed {r['seed']} {r['mode']}: {r['status']}", refresh=False)
            bar.update(1)

        try:
            sources = {p.name: p.source for p in profiles}
            if args.transport == "inproc" and getattr(args, "backend", "local") == "ray":
                from avp_experiment.ray_backend import run_ray

                errors = run_ray(todo, cfg, on_record, getattr(args, "address", None), args.workers, sources)
            elif args.transport == "inproc":
                errors = run_inproc(todo, cfg, args.workers, on_record, sources,
                                    getattr(args, "shared_pool", None))
            else:  # a plugin transport (.transports): the live DDS graph's is avp_bringup's
                from avp_experiment.transports import load_transport

                load_transport(args.transport)(todo, cfg, on_record, out / "logs", timeout=args.episode_timeout)
        finally:
            bar.close()
            writer.close()
            log_invocation(out, args, started, time.perf_counter() - t0, n_run, len(todo), commit)
    wanted = set(keys)
    records = [r for r in dedupe_egos(records) if record_key(r) in wanted]
    if any(fleet_names(u) for u in units):
        (out / "fleet.md").write_text(f"# Several egos\n\n{fleet_table(records)}\n\nColumns: docs/metrics.md, "
                                      "\"Several egos\".\n")
    summary = write_summary(out, records, skipped,
                            {"ade_horizon": cfg.ade_horizon, "t_final": cfg.t_final, "intent": ident["intent"] + own,
                             "seeds_without_scenario": bad_seeds, "sim_overrides": ident["config"]["sim_overrides"],
                             "protocol": cfg.protocol, "planner_overrides": cfg.planner_overrides,
                             "tracker_overrides": cfg.tracker_overrides},
                            {**{p.name: (p.group, p.label) for p in profiles},
                             **{u: ("fleet", u[len("fleet:"):]) for u in units if fleet_names(u)}})
    print(f"[avp experiment] ran {n_run} episodes; summary: {out / 'summary.md'}, plots in {out / 'plots'}/")
    if errors:
        print(f"[avp experiment] {len(errors)} episode(s) raised and are not in the results (listed above); "
              "run the same command to retry them", file=sys.stderr)
    return {"ran": n_run, "skipped_methods": skipped, "summary": summary, "errors": errors}


def dedupe_egos(records: list[dict]) -> list[dict]:
    """One record per (key, ego): a fleet episode cut off mid-write and run again leaves its first records twice."""
    last = {(record_key(r), r.get("ego")): i for i, r in enumerate(records)}
    return [r for i, r in enumerate(records) if last[(record_key(r), r.get("ego"))] == i]


def _parse_params(items: list[str] | None, specs: dict, flag: str, node: str) -> dict[str, Any]:
    """``KEY=VALUE`` items (VALUE parsed as YAML) -> {key: value}, checked against ``specs`` (ValueError naming
    the item)."""
    import yaml

    from avp_common.params import ParameterError, check_value

    out: dict[str, Any] = {}
    for item in items or []:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or key not in specs:
            raise ValueError(f"{flag} {item!r}: expected KEY=VALUE with KEY an {node} parameter (`avp params {node}`)")
        try:
            out[key] = check_value(specs[key], yaml.safe_load(raw), flag)
        except (ParameterError, yaml.YAMLError) as exc:
            raise ValueError(f"{flag} {item!r}: {exc}") from None
    return out


def parse_sim_params(items: list[str] | None) -> dict[str, Any]:
    """``--sim-param`` items, checked against the avp_sim parameter specs."""
    from avp_sim.params import SIM_PARAMS

    return _parse_params(items, {s.name: s for s in SIM_PARAMS}, "--sim-param", "avp_sim")


def _with_lot(sim_overrides: dict[str, Any], lot: str) -> dict[str, Any]:
    """``--lot FILE`` as the avp_sim parameter lot_file (an absolute path, so the workers and the graph find it);
    the file is loaded here once so that a bad lot is one error naming its field before any episode runs."""
    if not lot:
        return sim_overrides
    from avp_world.lot import load_lot

    path = str(Path(lot).resolve())
    load_lot(path)
    return {**sim_overrides, "lot_file": path}


def parse_planner_params(items: list[str] | None) -> dict[str, Any]:
    """``--planner-param`` items, checked against the avp_planner specs."""
    from avp_episode.profiles import _planner_specs

    return _parse_params(items, _planner_specs(), "--planner-param", "avp_planner")


def parse_tracker_params(items: list[str] | None) -> dict[str, Any]:
    """``--tracker-param`` items, checked against the avp_tracking specs (the tracker's, not its node's)."""
    from avp_episode.run_config import tracker_specs

    return _parse_params(items, tracker_specs(), "--tracker-param", "avp_tracker")


def run_command(args: argparse.Namespace) -> int:
    """``avp experiment`` with its exit status: 0 done, 1 some episodes raised (not recorded; the same command
    retries them), 2 bad arguments or run folder (one line naming what), 130 interrupted (Ctrl-C: the running
    episodes finish and are recorded), 143 terminated (SIGTERM: the workers end now, their episodes unrecorded)."""
    try:
        with end_workers_on_sigterm(f"[avp experiment] terminated; the finished episodes are in {args.out}/"
                                    f"{RESULTS_FILE}: run the same command to continue"):
            report = run_experiment(args)
    except (ValueError, ProfileError, RuntimeError) as exc:
        print(f"[avp experiment] {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"[avp experiment] interrupted; the finished episodes are in {args.out}/{RESULTS_FILE}: run the same "
              "command to continue", file=sys.stderr)
        return 130
    return 1 if report["errors"] else 0


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="avp experiment", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(p)
    return p


def _cell_args(argv: list[str]) -> argparse.Namespace:
    """The namespace of one suite cell's ``avp experiment`` arguments (:mod:`.headline`)."""
    return _parser().parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    return run_command(_parser().parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())

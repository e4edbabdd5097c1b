"""``avp experiment --sweep KEY=V1,V2,...`` and ``--ablation``: one Table I per setting.

A sweep runs the whole table (the same methods, seeds and modes) once per value of one avp_sim or avp_planner
parameter, each into its own resumable run folder ``OUT/<KEY>=<V>/`` (an ordinary ``avp experiment`` folder:
episodes.jsonl, summary.md, plots), then writes ``OUT/sweep.md`` (per value, method and mode: success, spots
stolen, collisions, failed-or-stolen with 95 % Wilson intervals, interrupted timesteps) and ``OUT/sweep_<mode>.png``
(:func:`.plots.plot_sweep`). The swept value applies to every method alike; scenario generation never reads the
method. The ablation does the same over the named variants of the safety extras
(:func:`.protocols.ablation_variants`: all on, all off, each off) into ``OUT/<variant>/`` and ``OUT/ablation.md``.
"""

from __future__ import annotations

import argparse
import copy
from collections.abc import Callable
from pathlib import Path

from avp_episode.metrics import mean_std, wilson

RATES = (("success", "success"), ("spot_stolen", "stolen"), ("collision", "collision"))


def parse_sweep(spec: str) -> tuple[str, str, list[str]]:
    """'KEY=V1,V2' -> (key, 'sim' | 'planner', raw values); ValueError naming the problem."""
    from avp_episode.profiles import _planner_specs
    from avp_sim.params import SIM_PARAMS

    key, sep, raw = spec.partition("=")
    key = key.strip()
    values = [v.strip() for v in raw.split(",") if v.strip()]
    if not sep or not values:
        raise ValueError(f"--sweep {spec!r}: expected KEY=V1,V2,...")
    if key in {s.name for s in SIM_PARAMS}:
        return key, "sim", values
    if key in _planner_specs():
        return key, "planner", values
    raise ValueError(f"--sweep {spec!r}: {key!r} is neither an avp_sim nor an avp_planner parameter")


def cell_stats(records: list[dict]) -> dict:
    """Counts and rates of one (setting, method, mode) cell: the row format of :func:`.plots.plot_sweep`."""
    n = len(records)
    out: dict = {"n": n}
    for field, name in RATES:
        out[name] = sum(bool(r[field]) for r in records)
    out["failed_or_stolen"] = sum((not r["success"]) or bool(r["spot_stolen"]) for r in records)
    ms = mean_std(r["interrupted_steps"] for r in records)
    out["interrupted_mean"], out["interrupted_sd"] = ms.get("mean", float("nan")), ms.get("std", float("nan"))
    return out


def _pct(k: int, n: int) -> str:
    if n == 0:
        return "–"
    lo, hi = wilson(k, n)
    return f"{100 * k / n:.1f} [{100 * lo:.1f}, {100 * hi:.1f}]"


def table(settings: list[str], cells: dict[tuple[str, str, str], dict], methods: list[str], modes: list[str],
          head: str) -> str:
    """Markdown: one row per (setting, mode, method)."""
    strip = f"{head}="
    lines = [f"| {head} | mode | method | n | success % | stolen % | collision % | failed or stolen % | "
             "interrupted |", "|---|---|---|--:|--:|--:|--:|--:|--:|"]
    for s in settings:
        for mode in modes:
            for m in methods:
                c = cells.get((s, m, mode))
                if not c:
                    continue
                lines.append(f"| {s.removeprefix(strip)} | {mode} | {m} | {c['n']} | {_pct(c['success'], c['n'])} | "
                             f"{_pct(c['stolen'], c['n'])} | {_pct(c['collision'], c['n'])} | "
                             f"{_pct(c['failed_or_stolen'], c['n'])} | {c['interrupted_mean']:.2f} |")
    return "\n".join(lines) + "\n"


def _run_settings(args: argparse.Namespace, settings: dict[str, dict[str, list[str]]],
                  run_one: Callable[[argparse.Namespace], dict]) -> tuple[dict, list[str], list[str], list[str]]:
    """Run the table once per named setting ({name: {'sim_param': [...], 'planner_param': [...]}})."""
    from avp_experiment.results import read_results, records_file

    cells: dict[tuple[str, str, str], dict] = {}
    methods: list[str] = []
    modes: list[str] = []
    errors: list[str] = []
    for name, extra in settings.items():
        sub = copy.copy(args)
        sub.sweep, sub.ablation, sub.out = None, False, str(Path(args.out) / name)
        sub.sim_param = list(args.sim_param or []) + extra.get("sim_param", [])
        sub.planner_param = list(args.planner_param or []) + extra.get("planner_param", [])
        print(f"[avp experiment] --- {name} -> {sub.out}", flush=True)
        report = run_one(sub)
        errors += report.get("errors", [])
        by: dict[tuple[str, str], list[dict]] = {}
        for r in read_results(records_file(sub.out)):
            by.setdefault((r["method"], r["mode"]), []).append(r)
        for (m, mode), recs in by.items():
            cells[(name, m, mode)] = cell_stats(recs)
            methods += [m] if m not in methods else []
            modes += [mode] if mode not in modes else []
    return cells, methods, sorted(modes), errors


def run_sweep(args: argparse.Namespace, run_one: Callable[[argparse.Namespace], dict]) -> dict:
    """The ``--sweep`` command: see the module docstring."""
    from avp_report.plots import plot_sweep

    key, kind, values = parse_sweep(args.sweep)
    flag = "sim_param" if kind == "sim" else "planner_param"
    settings = {f"{key}={v}": {flag: [f"{key}={v}"]} for v in values}
    cells, methods, modes, errors = _run_settings(args, settings, run_one)
    out = Path(args.out)
    names = list(settings)
    text = [f"# Sweep of `{key}` ({kind} parameter), protocol `{args.protocol}`\n",
            f"`{_command(args)}`\n", table(names, cells, methods, modes, key)]
    for mode in modes:
        rows = {m: [cells.get((n, m, mode), {"n": 0}) for n in names] for m in methods}
        png = plot_sweep(out / f"sweep_{mode}.png", key, [_number(v) for v in values], rows,
                         title=f"{mode.replace('_', '-')} agents, protocol {args.protocol}")
        text.append(f"\n![{mode}]({png.name})\n")
    (out / "sweep.md").write_text("\n".join(text))
    print(f"[avp experiment] sweep table: {out / 'sweep.md'}")
    return {"ran": sum(c["n"] for c in cells.values()), "errors": errors, "cells": cells}


def run_ablation(args: argparse.Namespace, run_one: Callable[[argparse.Namespace], dict]) -> dict:
    """The ``--ablation`` command: see the module docstring."""
    from avp_episode.protocols import SAFETY_EXTRAS, ablation_variants

    variants = ablation_variants()
    settings = {name: {"planner_param": [f"{k}={str(v).lower()}" for k, v in params.items()]}
                for name, params in variants.items()}
    cells, methods, modes, errors = _run_settings(args, settings, run_one)
    out = Path(args.out)
    extras = "; ".join(f"`{n}`: " + ", ".join(f"{k} {on}→{off}" for k, (on, off) in p.items())
                       for n, p in SAFETY_EXTRAS.items())
    text = [f"# Ablation of the safety extras, protocol `{args.protocol}`\n", f"`{_command(args)}`\n",
            f"Extras (on → off; off is the paper's §V-D): {extras}\n", table(list(settings), cells, methods, modes,
                                                                              "variant")]
    (out / "ablation.md").write_text("\n".join(text))
    print(f"[avp experiment] ablation table: {out / 'ablation.md'}")
    return {"ran": sum(c["n"] for c in cells.values()), "errors": errors, "cells": cells}


def _number(v: str):
    try:
        return float(v)
    except ValueError:
        return v


def _command(args: argparse.Namespace) -> str:
    parts = ["avp experiment", f"--protocol {args.protocol}", f"--scenarios {args.scenarios}",
             f"--seed-base {args.seed_base}", f"--mode {args.mode}", f"--methods {args.methods}"]
    parts += [f"--sim-param {p}" for p in args.sim_param or []]
    parts += [f"--planner-param {p}" for p in args.planner_param or []]
    parts += [f"--sweep {args.sweep}"] if args.sweep else []
    parts += ["--ablation"] if args.ablation else []
    return " ".join(parts + [f"--out {args.out}"])
